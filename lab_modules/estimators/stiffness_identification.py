"""Least-squares identification of the force-current and force-position factors
k_i, k_s of the axial bearing at an operating point (paper 002, §C, eq. 26-31).

At each operating point (i*, x*) the paper samples the magnet force at the nine
points i* + {-Δi, 0, +Δi} × x* + {-Δx, 0, +Δx} (Δi = 0.01 A, Δx = 0.01 mm, eq. 27)
and fits

    F = k_i·i + k_s·x        (eq. 26, no constant term)

by least squares, θ = (AᵀA)⁻¹AᵀY (eq. 31).  Without a constant the plane must
pass through the origin, so away from the centre the fitted factors are those of
the plane through the origin that best matches the force near (i*, x*), not the
tangent derivatives of eq. 3-4; this is what Tables 4 and 5 print (e.g. at
x = -0.5 mm, i = -1.5 A: tangent 17.87 N/A and 35.73 N/mm, the tables 7.14 and
32.16).  ``intercept=True`` adds the constant term; the fit then tends to the
tangent plane as the stencil shrinks.  The fit is the same in SI units or in
the paper's A and mm (rescaling a column rescales only its coefficient).

The force "measurements" may carry Gaussian noise (σ in N, one draw per sample):
a small stencil sees little curvature (bias) but divides the noise by a small
lever (variance).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from lab_modules.plants.axial_bearing import (
    AXIAL,
    GRID_CURRENTS_A,
    GRID_POSITIONS_M,
    AxialBearing,
    magnet_force,
)

#: The paper's stencil (eq. 27): ±0.01 A, ±0.01 mm.
PAPER_STENCIL_A, PAPER_STENCIL_M = 0.01, 0.01e-3
_OFFSETS = np.array([-1.0, 0.0, 1.0])


def lsm_factors(current_a, position_m, stencil_a: float = PAPER_STENCIL_A,
                stencil_m: float = PAPER_STENCIL_M, force_noise_n: float = 0.0,
                rng: np.random.Generator | None = None, intercept: bool = False,
                bearing: AxialBearing = AXIAL, k_magnet: float | None = None):
    """(k_i [N/A], k_s [N/m]) fitted at each operating point (arrays broadcast)."""
    i0, x0 = np.broadcast_arrays(np.asarray(current_a, float), np.asarray(position_m, float))
    di, dx = np.meshgrid(_OFFSETS * stencil_a, _OFFSETS * stencil_m, indexing="ij")
    currents = i0[..., None] + di.ravel()
    positions = x0[..., None] + dx.ravel()
    k = bearing.k_magnet_n_m2_per_a2 if k_magnet is None else k_magnet
    force = magnet_force(currents, positions, k, bearing.nominal_gap_m, bearing.bias_current_a)
    if force_noise_n > 0.0:
        rng = rng if rng is not None else np.random.default_rng(0)
        force = force + rng.normal(0.0, force_noise_n, force.shape)
    columns = [currents, positions] + ([np.ones_like(currents)] if intercept else [])
    A = np.stack(columns, axis=-1)                                 # (..., 9, p)
    theta = np.linalg.solve(np.swapaxes(A, -1, -2) @ A, (np.swapaxes(A, -1, -2) @ force[..., None]))[..., 0]
    return theta[..., 0], theta[..., 1]


def lsm_tables(**kwargs) -> tuple[np.ndarray, np.ndarray]:
    """Tables 4 and 5: (k_i [N/A], k_s [N/m]) on the 5×5 grid, rows x, columns i."""
    currents, positions = np.meshgrid(GRID_CURRENTS_A, GRID_POSITIONS_M, indexing="xy")
    return lsm_factors(currents, positions, **kwargs)


@njit(cache=True, nogil=True)
def lsm_factors_at(current_a, position_m, stencil_a, stencil_m, k_magnet, s0, i0):
    """Noise-free, no-intercept fit (eq. 26-31) at one operating point, in closed
    form (the 2×2 normal equations); used on line by the exact-LSM filter."""
    a = b = c = p = q = 0.0
    for u in (-1.0, 0.0, 1.0):
        for w in (-1.0, 0.0, 1.0):
            i = current_a + u * stencil_a
            x = position_m + w * stencil_m
            f = magnet_force(i, x, k_magnet, s0, i0)
            a += i * i
            b += i * x
            c += x * x
            p += i * f
            q += x * f
    det = a * c - b * b
    return (c * p - b * q) / det, (a * q - b * p) / det
