"""ADALINE (adaptive linear element) for online identification (paper 002, §C,
eq. 22-25, Figs. 5-6, 11-12).

An ADALINE is a linear neuron y = Σ w_j x_j (eq. 22-23, no bias, identity
activation) whose weights follow the Widrow-Hoff (LMS) rule

    w_j(k+1) = w_j(k) + η e(k) x_j(k),   e = target - y                (eq. 24, Δw of [6], [7])

Two uses in the paper (their regressors did not survive the text; reconstructed):

(a) MISO: "the system (rotor dynamic - magnet force)", four inputs, the fourth
    weight w₄ = F_Magnet(k).  Read as the discretised rotor motion
    x(k+1) - 2x(k) + x(k-1) = T²/m (F_Magnet - m g + F_St) (eq. 15-16), that form
    cannot work here: its gravity and force inputs are both constants, so only
    their sum is identifiable, and the second difference of the measured position
    (σ ≈ 9 µm at the paper's noise, T = 100 µs) carries about
    √6 · m σ / T² ≈ 1 kN of noise per sample.  The lab's MISO ADALINE
    (``miso_step``, ``miso_run``) identifies the magnet force from the two inputs
    of the force map instead, F̂ = w_i·i + w_s·x (eq. 26's model, no constant):
    the online counterpart of the least squares of Tables 4-5, whose weights are
    the local k_i [N/A] and k_s [N/mm] of the current operating point (x in mm,
    so that one η serves both weights).  A lab reconstruction, stated as such.
(b) SISO: F_Magnet = k_Magnet · φ(i, x), φ = (i0+i)²/(s0-x)² - (i0-i)²/(s0+x)²
    (eq. 1); the weight is k_Magnet.  ``siso_step``, ``siso_run``; the lab works in the
    paper's units (φ in A²/mm², k_Magnet in N·mm²/A²) so that η is a plain number.

The update is proportional to the input: where the magnet force is zero (φ = 0,
e.g. a horizontal axis at the centre without load) nothing is identified.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def siso_step(weight, regressor, target, rate):
    """One LMS step of the SISO ADALINE; returns the new weight."""
    error = target - weight * regressor
    return weight + rate * error * regressor


@njit(cache=True, nogil=True)
def siso_run(weight, regressors, targets, rate, out):
    """The SISO ADALINE over a record (``siso_step`` at every sample): writes the a-priori estimates
    F̂(k) = ŵ(k) φ(k) into ``out``; returns the last weight."""
    for k in range(targets.size):
        out[k] = weight * regressors[k]
        weight = siso_step(weight, regressors[k], targets[k], rate)
    return weight


@njit(cache=True, nogil=True)
def miso_step(weights, inputs, target, rate):
    """One LMS step of the MISO ADALINE (eq. 24 for every weight), in place;
    returns the output before the step (the a-priori estimate ŷ = wᵀu)."""
    estimate = 0.0
    for j in range(weights.size):
        estimate += weights[j] * inputs[j]
    error = target - estimate
    for j in range(weights.size):
        weights[j] += rate * error * inputs[j]
    return estimate


@njit(cache=True, nogil=True)
def miso_run(weights, currents_a, positions_mm, forces_n, rate, out):
    """The MISO ADALINE over a record: inputs (i [A], x [mm]), target the measured force [N].
    Writes rows (F̂ a priori [N], w_i [N/A], w_s [N/mm]) into ``out``; ``weights`` carries on."""
    inputs = np.empty(2)
    for k in range(forces_n.size):
        inputs[0] = currents_a[k]
        inputs[1] = positions_mm[k]
        out[k, 0] = miso_step(weights, inputs, forces_n[k], rate)
        out[k, 1] = weights[0]
        out[k, 2] = weights[1]
