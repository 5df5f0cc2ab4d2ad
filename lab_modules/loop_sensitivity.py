"""Margins and sensitivity of a loop broken at the plant input (``analysis.loop_at_plant_input``), as
AMB engineers grade a loop: gain margins up and down, phase margin, |S|max and its ISO 14839-3 zone."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.optimize

#: ISO 14839-3 zones by the peak of the sensitivity function |S|max (absolute value, not dB)
ISO_14839_ZONES = (("A", 3.0), ("B", 4.0), ("C", 5.0), ("D", float("inf")))


def iso_zone(peak: float) -> str:
    """ISO 14839-3 zone of a sensitivity peak |S|max: A < 3, B < 4, C < 5, D above."""
    return next(zone for zone, limit in ISO_14839_ZONES if peak < limit)


@dataclass(frozen=True)
class Margins:
    """Stability margins of an open loop L (loop broken at the plant input) and the peak of
    the sensitivity S = 1 / (1 + L).  An open-loop unstable plant (the magnetic bearing) is
    stable only between two gains, so it has a gain margin upwards and one downwards."""

    gain_margin: float            # gain factor that reaches instability upwards (inf: none)
    gain_margin_down: float       # ... downwards (0: none)
    phase_margin_deg: float       # smallest over the gain crossovers (inf: none)
    gain_crossover_rad_s: float   # where |L| = 1 with the smallest phase margin (NaN: none)
    sensitivity_peak: float       # |S|max
    sensitivity_peak_rad_s: float
    stable: bool                  # closed loop 1 / (1 + L) stable

    @property
    def zone(self) -> str:
        return iso_zone(self.sensitivity_peak) if self.stable else "D"


def frequency_grid(system, points: int = 800, low_rad_s: float = 1.0) -> np.ndarray:
    """Log-spaced angular frequencies [rad/s] up to the Nyquist frequency of a discrete system
    (or 1e5 rad/s for a continuous one)."""
    high = np.pi / system.dt if system.dt else 1e5
    return np.logspace(np.log10(low_rad_s), np.log10(0.999 * high), points)


def open_loop_response(open_loop, omega) -> np.ndarray:
    """L(jω) (or L(e^{jωT})) of a SISO system on ``omega`` [rad/s]: for a state space one batched
    solve of (zI - A) x = B (what python-control's ``frequency_response`` returns, without its
    per-call overhead: the margin search evaluates single frequencies many times)."""
    if not isinstance(open_loop, control.StateSpace):
        return np.asarray(np.squeeze(control.frequency_response(open_loop, np.atleast_1d(omega)).complex))
    A, B, C, D = (np.asarray(M, dtype=float) for M in (open_loop.A, open_loop.B, open_loop.C, open_loop.D))
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    z = np.exp(1j * w * open_loop.dt) if open_loop.dt else 1j * w
    if A.shape[0] == 0:
        return np.squeeze(np.full(w.shape, D[0, 0], dtype=complex))
    with np.errstate(all="ignore"):
        x = np.linalg.solve(z[:, None, None] * np.eye(A.shape[0]) - A, np.broadcast_to(B[:, :1], (w.size,) + B[:, :1].shape))
    return np.squeeze(x[..., 0] @ C[0] + D[0, 0])


def _roots(f, omega: np.ndarray, values: np.ndarray) -> list[float]:
    """Frequencies where ``f`` changes sign between grid points, refined by Brent's method."""
    found = []
    for k in np.nonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)[0]:
        found.append(scipy.optimize.brentq(f, omega[k], omega[k + 1], xtol=1e-9 * omega[k]))
    return found


def _closed_loop_stable(open_loop, gain: float) -> bool:
    """Whether u = -gain · y closes ``open_loop`` stably (poles inside the unit circle, or left half-plane)."""
    poles = np.asarray(control.feedback(gain * open_loop, 1).poles())
    return bool(np.all(np.abs(poles) < 1.0)) if open_loop.dt else bool(np.all(poles.real < 0))


def loop_margins(open_loop, omega: np.ndarray | None = None) -> Margins:
    """Margins from the frequency response on ``omega`` (log grid to Nyquist by default):
    phase crossovers where Im L changes sign with Re L < 0 and gain crossovers where |L| = 1,
    each refined by Brent's method; |S|max refined around its grid peak."""
    omega = frequency_grid(open_loop) if omega is None else np.asarray(omega, dtype=float)
    L = open_loop_response(open_loop, omega)

    def at(w: float) -> complex:
        return complex(open_loop_response(open_loop, w))
    gains = []
    for w in _roots(lambda w: at(w).imag, omega, L.imag):
        value = at(w)
        if value.real < 0:
            gains.append(1.0 / abs(value))
    # L is real at ω = 0 (and at the Nyquist frequency of a discrete loop): a crossing there
    # (an unstable plant under a loop without integrator: the lower gain margin) has no sign change
    for point in ((1.0, -1.0) if open_loop.dt else (0.0,)):
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")              # singular at z = 1 for a loop with an integrator
            value = complex(np.squeeze(open_loop(point)))
        if np.isfinite(value) and value.real < 0 and abs(value.imag) <= 1e-9 * abs(value):
            gains.append(1.0 / abs(value))
    phase_margins = [(float(np.degrees(np.angle(-at(w)))), w)
                     for w in _roots(lambda w: abs(at(w)) - 1.0, omega, np.abs(L) - 1.0)]
    pm, wc = min(phase_margins, key=lambda p: abs(p[0]), default=(np.inf, np.nan))
    stable = _closed_loop_stable(open_loop, 1.0)
    if not stable:
        # with several unstable closed-loop poles, a crossing of -1 may move one pair and leave others:
        # only the gain factors where stability changes are margins
        gains = [g for g in gains if _closed_loop_stable(open_loop, 0.99 * g) != _closed_loop_stable(open_loop, 1.01 * g)]
    values = 1.0 / np.abs(1.0 + L)
    k = int(np.argmax(values))
    lo, hi = omega[max(k - 1, 0)], omega[min(k + 1, len(omega) - 1)]
    refined = scipy.optimize.minimize_scalar(lambda w: -1.0 / abs(1.0 + at(w)), bounds=(lo, hi),
                                             method="bounded", options={"xatol": 1e-7 * omega[k]})
    peak, peak_w = (-refined.fun, refined.x) if -refined.fun > values[k] else (values[k], omega[k])
    return Margins(min((g for g in gains if g > 1), default=np.inf),
                   max((g for g in gains if g < 1), default=0.0),
                   abs(pm) if np.isfinite(pm) else np.inf, float(wc), float(peak), float(peak_w), stable)
