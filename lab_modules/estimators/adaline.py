"""ADALINE (adaptive linear element) for online identification (paper 002, §C,
eq. 22-25, Figs. 5-6, 11-12).

An ADALINE is a linear neuron y = Σ w_j x_j (eq. 22-23, no bias, identity
activation) whose weights follow the Widrow-Hoff (LMS) rule

    w_j(k+1) = w_j(k) + η e(k) x_j(k),   e = target - y                (eq. 24, Δw of [6], [7])

Two uses in the paper (their regressors did not survive the text; reconstructed):

(a) MISO: the rotor's motion x(k+1) - 2x(k) + x(k-1) = T²/m (F_Magnet - m g + F_St)
    (eq. 15-16); with the kinematic weights known, the one adapted weight is
    w₄ = F_Magnet(k), input T²/m.  Not built in the lab: the SISO ADALINE below
    learns from a measured force instead (see ``loops.axial_bearing_loop``).
(b) SISO: F_Magnet = k_Magnet · φ(i, x), φ = (i0+i)²/(s0-x)² - (i0-i)²/(s0+x)²
    (eq. 1); the weight is k_Magnet.  ``siso_step``; the lab works in the
    paper's units (φ in A²/mm², k_Magnet in N·mm²/A²) so that η is a plain number.

The update is proportional to the input: where the magnet force is zero (φ = 0,
e.g. a horizontal axis at the centre without load) nothing is identified.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, nogil=True)
def siso_step(weight, regressor, target, rate):
    """One LMS step of the SISO ADALINE; returns the new weight."""
    error = target - weight * regressor
    return weight + rate * error * regressor

