"""Inductance from the PWM current ripple (paper 001, §3 and §5).

Per half period (charging phase I, v ≈ +v_bat; discharging phase II,
v ≈ −v_bat) the samples inside a window [m_s, m_e] fit the line

    i_k = i_ms + (T_s / L) Δψ̃_k,   Δψ̃_k = Σ_{j=m_s}^{k−1} (v_j − R̂ i_j)      (eq. 7-9)

by least squares (eq. 10), so L̂ = T_s / θ̂₂.  Eq. 7 prints ``v_j + R i_j``;
Faraday's law (eq. 3, 5) needs ``v_j − R̂ i_j``.  The misprint cancels in
the averaged estimate but makes each half-period estimate wrong by tens of
per cent (at 4 mm: +71 % in phase I, −42 % in phase II).

The two half-period estimates are combined (eq. 18) to cancel a resistance
error ΔR and the motion term L̇ (eq. 17: L̄ = L̂ − (ΔR + L̇) ī Δt / Δi):

    L̄ = (L̂ᴵ Δiᴵ īᴵᴵ Δtᴵᴵ − L̂ᴵᴵ Δiᴵᴵ īᴵ Δtᴵ) / (Δiᴵ īᴵᴵ Δtᴵᴵ − Δiᴵᴵ īᴵ Δtᴵ).

Eq. 18 prints ``īᴵ`` in the first term of the denominator; eliminating
(ΔR + L̇) from eq. 17 for both phases gives ``īᴵᴵ`` (as eq. 31 has it), and
only then do the two weights add up to one.  Δi is the current change of the
fitted line over the window (not the difference of two noisy end samples),
ī the window's mean current and Δt the window's length.

Variance (eq. 26-32): σ̂²(i) = eᵀe / (M − d) with M samples and d = 2
parameters (eq. 28 prints M + d: that is not the unbiased estimate),
σ̂²(θ̂₂) = σ̂²(i) s²² (eq. 29), σ̂²(L̂) = (T_s/θ̂₂²)² σ̂²(θ̂₂) (eq. 30),
σ̂²(L̄) = wᴵ² σ̂²(L̂ᴵ) + wᴵᴵ² σ̂²(L̂ᴵᴵ) with the weights of eq. 18 (eq. 31).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Fields of one half-period fit, in the order ``fit_half_period`` returns them.
FIT_FIELDS = ("inductance_h", "variance_inductance_h2", "variance_current_a2", "delta_current_a",
              "mean_current_a", "window_s", "initial_current_a")


@njit(cache=True, nogil=True)
def fit_half_period(current_a, voltage_v, start, stop, resistance_ohm, sample_time_s, dof_sign, out):
    """Eq. 7-10 and 28-30 over samples start..stop (inclusive) of one phase.

    ``voltage_v[j]`` is the voltage applied from sample j to j+1 (forward
    Euler, eq. 7).  ``dof_sign`` = −1 divides the residual sum by M − d,
    +1 by the printed M + d.  Fills ``out`` with FIT_FIELDS."""
    m = stop - start + 1
    flux = np.empty(m)                          # Δψ̃_k [V·samples], eq. 7 (with − R̂ i)
    flux[0] = 0.0
    for k in range(1, m):
        j = start + k - 1
        flux[k] = flux[k - 1] + voltage_v[j] - resistance_ohm * current_a[j]
    mean_x = 0.0
    mean_y = 0.0
    for k in range(m):
        mean_x += flux[k]
        mean_y += current_a[start + k]
    mean_x /= m
    mean_y /= m
    sxx = 0.0
    sxy = 0.0
    for k in range(m):
        dx = flux[k] - mean_x
        sxx += dx * dx
        sxy += dx * (current_a[start + k] - mean_y)
    slope = sxy / sxx                           # θ̂₂ = T_s / L̂, eq. 10
    offset = mean_y - slope * mean_x            # θ̂₁ = î(m_s)
    residuals = 0.0
    for k in range(m):
        e = current_a[start + k] - offset - slope * flux[k]
        residuals += e * e
    variance_current = residuals / (m + dof_sign * 2)          # eq. 28
    variance_slope = variance_current / sxx                     # eq. 29, s²² = 1 / Σ(x − x̄)²
    out[0] = sample_time_s / slope                              # L̂
    out[1] = (sample_time_s / slope**2) ** 2 * variance_slope   # eq. 30
    out[2] = variance_current
    out[3] = slope * flux[m - 1]                                # Δi of the fitted line
    out[4] = mean_y                                             # ī of the window
    out[5] = (m - 1) * sample_time_s                            # Δt of the window
    out[6] = offset


@njit(cache=True, nogil=True)
def average(fit_1, fit_2):
    """Eq. 18 and 31: (L̄, σ̂²(L̄), wᴵ, wᴵᴵ) from the two half-period fits."""
    term_1 = fit_1[3] * fit_2[4] * fit_2[5]          # Δiᴵ īᴵᴵ Δtᴵᴵ
    term_2 = -fit_2[3] * fit_1[4] * fit_1[5]         # −Δiᴵᴵ īᴵ Δtᴵ (Δiᴵᴵ < 0)
    denominator = term_1 + term_2
    w_1 = term_1 / denominator
    w_2 = term_2 / denominator
    mean = w_1 * fit_1[0] + w_2 * fit_2[0]
    variance = w_1**2 * fit_1[1] + w_2**2 * fit_2[1]
    return mean, variance, w_1, w_2


def fit(current_a, voltage_v, start: int, stop: int, resistance_ohm: float, sample_time_s: float,
        dof: str = "M-d") -> dict:
    """One half-period fit from Python (eq. 7-10, 28-30) as a dict of FIT_FIELDS."""
    out = np.empty(len(FIT_FIELDS))
    fit_half_period(np.ascontiguousarray(current_a, dtype=float), np.ascontiguousarray(voltage_v, dtype=float),
                    int(start), int(stop), float(resistance_ohm), float(sample_time_s),
                    -1 if dof == "M-d" else 1, out)
    return dict(zip(FIT_FIELDS, out))


def weights(delta_current_a, mean_current_a, window_s) -> tuple[float, float]:
    """The weights (wᴵ, wᴵᴵ) of eq. 18 from (Δi, ī, Δt) of both phases."""
    term_1 = delta_current_a[0] * mean_current_a[1] * window_s[1]
    term_2 = -delta_current_a[1] * mean_current_a[0] * window_s[0]
    return term_1 / (term_1 + term_2), term_2 / (term_1 + term_2)


def predicted_sigma_inductance_h(inductance_h: float, sigma_current_a: float, effective_voltage_v: float,
                                 samples: int, sample_time_s: float) -> float:
    """σ(L̂) of eq. 28-30 for a straight ramp: Σ(x − x̄)² = v² (M³ − M)/12 in Δψ̃ units, so
    σ(L̂) = L² σ(i) / (T_s v √((M³ − M)/12))."""
    return inductance_h**2 * sigma_current_a / (sample_time_s * effective_voltage_v
                                               * math.sqrt((samples**3 - samples) / 12.0))
