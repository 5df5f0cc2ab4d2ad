"""Is a filter consistent?  NEES and NIS over a window of its history, with 95 % χ² bounds.

For a consistent filter (Bar-Shalom, Li and Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, §5.4):

    NEES  ε_k = (x_k − x̂⁺_k)ᵀ (P⁺_k)⁻¹ (x_k − x̂⁺_k)   ~ χ²(n)      (the n states whose truth is known)
    NIS   ε_k = ν_kᵀ S_k⁻¹ ν_k                            ~ χ²(m)

and the mean of N independent samples, times N, is χ²(N n) (resp. χ²(N m)), so the window's
mean lies inside [χ²_{0.025}(N d) / N, χ²_{0.975}(N d) / N] 95 % of the time.

The innovations of a consistent filter are white, so the NIS samples are independent.  The
estimation error is not: it is correlated over the filter's time constant, and a window of N
samples holds fewer independent NEES samples, N / τ with τ = 1 + 2 Σ ρ_j the integrated
autocorrelation time of the NEES sequence (the sum stops at the first ρ_j ≤ 0).  The NEES
bounds rest on that number (rounded down, at least 1), which widens them honestly.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.stats

from lab_modules.estimators.filter_history import FilterHistory

CONFIDENCE = 0.95


@dataclass(frozen=True)
class ConsistencyTest:
    """One test over a window: the mean normalised squared error and its 95 % bounds."""

    name: str                    # "NEES" or "NIS"
    mean: float                  # mean ε over the window (dimensionless)
    dof: int                     # degrees of freedom per sample (states or measurements tested)
    samples: int                 # samples in the window
    independent_samples: int     # the N the bounds rest on
    lower: float                 # χ²_{0.025}(N d) / N
    upper: float                 # χ²_{0.975}(N d) / N

    @property
    def inside(self) -> bool:
        return bool(self.lower <= self.mean <= self.upper)

    @property
    def verdict(self) -> str:
        """'consistent', or which way the filter is wrong."""
        if self.inside:
            return "consistent"
        return ("overconfident (P or S too small)" if self.mean > self.upper
                else "too cautious (P or S too large)")


@lru_cache(maxsize=4096)
def bounds(independent_samples: int, dof: int) -> tuple[float, float]:
    """95 % bounds on the mean of ``independent_samples`` χ²(``dof``) samples (remembered: a live
    readout asks for the same few every second, and each χ² quantile costs ~0.2 ms)."""
    total = independent_samples * dof
    tail = (1.0 - CONFIDENCE) / 2.0
    lower, upper = scipy.stats.chi2.ppf([tail, 1.0 - tail], total) / independent_samples
    return float(lower), float(upper)


def integrated_autocorrelation_time(values: np.ndarray) -> float:
    """τ = 1 + 2 Σ_{j≥1} ρ_j, the sum up to the first non-positive autocorrelation ρ_j."""
    centred = np.asarray(values, dtype=float) - np.mean(values)
    variance = float(np.dot(centred, centred))
    if variance == 0.0 or len(centred) < 3:
        return 1.0
    spectrum = np.fft.rfft(centred, 2 * len(centred))
    rho = np.fft.irfft(spectrum * np.conj(spectrum))[1:len(centred)] / variance
    positive = np.argmax(rho <= 0.0) if np.any(rho <= 0.0) else len(rho)
    return 1.0 + 2.0 * float(np.sum(rho[:positive]))


def nees_samples(history: FilterHistory) -> tuple[np.ndarray, int]:
    """ε_k of every sample against the known true states, and how many states that is."""
    known = np.all(np.isfinite(history.truth), axis=0)
    error = (history.truth - history.x_post)[:, known]
    P = history.P_post[:, known][:, :, known]
    return np.einsum("ki,ki->k", error, np.linalg.solve(P, error[..., None])[..., 0]), int(known.sum())


def nis_samples(history: FilterHistory) -> np.ndarray:
    """ε_k = ν_kᵀ S_k⁻¹ ν_k of every sample."""
    nu = history.innovation
    return np.einsum("ki,ki->k", nu, np.linalg.solve(history.S, nu[..., None])[..., 0])


def normalised_test(name: str, samples: np.ndarray, dof: int, independent: int) -> ConsistencyTest:
    """The window's mean of ``samples`` (each χ²(``dof``) if consistent) against its bounds."""
    independent = max(1, min(int(independent), len(samples)))
    return ConsistencyTest(name, float(np.mean(samples)), dof, len(samples), independent, *bounds(independent, dof))


def consistency(history: FilterHistory, window: int | None = None) -> tuple[ConsistencyTest, ...]:
    """(NEES, NIS) over the newest ``window`` samples of ``history`` (None: all of it); NIS
    alone when no true state is known (a recording)."""
    if window is not None:
        history = history.rows(max(0, len(history) - int(window)), len(history))
    nees, states = nees_samples(history)
    nis = normalised_test("NIS", nis_samples(history), history.model.H.shape[0], len(history))
    if states == 0:
        return (nis,)
    return normalised_test("NEES", nees, states, int(len(nees) / integrated_autocorrelation_time(nees))), nis
