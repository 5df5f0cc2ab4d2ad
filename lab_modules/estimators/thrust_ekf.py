"""Paper 003's filter re-linearised at its own estimate every sample (an extended Kalman filter,
§1.2: "linearised about the optimal state estimate"), and the touchdown stop in any thrust filter.

``thrust_kalman`` linearises eq. 2 once at (i0, x0) (eq. 4) and discretises by eq. 9-11.  The
extended filter applies the same second-order Taylor series to eq. 2 itself, at the corrected
estimate (x̂, v̂) and the measured coil current i held over the sample T:

    a = f(x̂, i) / m,   a_x = ∂f/∂x (x̂, i) / m                      (eq. 2, ``force_and_stiffness``)
    x̂⁻ = x̂ + T v̂ + T²/2 · a
    v̂⁻ = v̂ + T a + T²/2 · a_x v̂                                      (eq. 9 with A_k at the estimate)
    Φ_k = I + A_k T + (A_k T)²/2,   A_k = [[0, 1], [a_x, 0]]
    P⁻ = Φ_k P Φ_kᵀ + G_d Q G_dᵀ,   G_d = (T I + A_k T²/2) G = (T²/2m, T/m)   (eq. 11, 15)

G_d does not depend on a_x, so Q_d is the linear filter's.  With the linear force law (eq. 4) these
lines are eq. 9-11 exactly, and at the centre (x̂ = 0, i = 0) a_x = 4 k_f i0²/(m x0³) = |k_x|/m: the
two filters share their steady state.  Neither filter models gravity (the vertical variant's
weight is a force the filter's Q must absorb).

The stop: the touchdown bearing holds the collar inside ±c.  A filter that knows it clamps its
prediction as the plant clamps the collar: x̂⁻ = ±c, and v̂⁻ = 0 when it points into the stop.  The
correction stays the generic one (x̂⁺ may lie a sensor-noise width beyond the stop), so the filter
debugger's replay, which corrects generically, is exact.  The clamp leaves P as it is.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from lab_modules.estimators.filter_history import FilterModel
from lab_modules.estimators.kalman import STATE_SIZE, KalmanFilter, predict, propagate_covariance
from lab_modules.plants.thrust_bearing import force_and_stiffness

JIT = {"nogil": True, "cache": True, "error_model": "numpy"}
MODEL_STATES = 2                       # (x [m], v [m/s]) inside the padded arrays

#: The predictions in LaTeX (the filter debugger's equations): extended, and linear with the stop.
EXTENDED_PREDICTION_LATEX = (
    (r"\hat{x}^+ + T\hat{v}^+ + \tfrac{T^2}{2}\tfrac{f(\hat{x}^+, i)}{m},\ "
     r"\hat{v}^+ + T\tfrac{f}{m} + \tfrac{T^2}{2}\tfrac{\partial f/\partial x}{m}\hat{v}^+"),
    r"\Phi_k P^+_{k-1}\Phi_k^T + Q,\ \Phi_k = I + A_k T + (A_k T)^2/2")
CLAMPED_PREDICTION_LATEX = (r"\mathrm{stop}(\Phi\hat{x}^+_{k-1} + \Gamma u_{k-1})", r"\Phi P^+_{k-1}\Phi^T + Q")


class ThrustPrediction(NamedTuple):
    """How a thrust filter predicts (module docstring), for the compiled loop."""

    extended: bool            # re-linearise eq. 2 at the estimate; False: the fixed Φ, B_d of the filter's arrays
    constants: np.ndarray     # (7,) ``ThrustBearing.force_constants``: m [kg], k_i [N/A], |k_x| [N/m], i0 [A],
    #                           k_f [N m²/A²], x0 [m], smallest gap [m]
    sample_time_s: float      # T [s]
    stop_m: float             # the touchdown clearance the filter knows [m]; inf: no stop in its model
    transition: np.ndarray    # (STATE_SIZE, STATE_SIZE) Φ_k of the last extended prediction, padded, in place


def thrust_prediction(bearing, extended: bool, knows_stop: bool) -> ThrustPrediction:
    """The bundle for ``bearing`` (a ``ThrustBearing``)."""
    return ThrustPrediction(extended=extended, constants=bearing.force_constants(),
                            sample_time_s=bearing.sample_time_s,
                            stop_m=bearing.touchdown_clearance_m if knows_stop else np.inf,
                            transition=np.zeros((STATE_SIZE, STATE_SIZE)))


@numba.njit(**JIT)
def extended_prediction(x_hat, P, i, Q, prediction, work_P):
    """x̂⁻, P⁻ of the module docstring in place, with the coil current i [A]; Φ_k into
    ``prediction.transition``."""
    T, constants = prediction.sample_time_s, prediction.constants
    force, slope = force_and_stiffness(x_hat[0], i, constants)
    a, a_x = force / constants[0], slope / constants[0]       # a = f/m [m/s²], a_x = ∂f/∂x / m [1/s²]
    x, v = x_hat[0], x_hat[1]
    x_hat[0] = x + T * v + 0.5 * T * T * a                    # x̂⁻ = x̂ + T v̂ + T²/2 a
    x_hat[1] = v + T * a + 0.5 * T * T * a_x * v              # v̂⁻ = v̂ + T a + T²/2 a_x v̂
    Phi = prediction.transition
    Phi[0, 0] = 1.0 + 0.5 * a_x * T * T                       # Φ_k = I + A_k T + (A_k T)²/2
    Phi[0, 1] = T
    Phi[1, 0] = a_x * T
    Phi[1, 1] = Phi[0, 0]
    propagate_covariance(P, Phi, Q, work_P, MODEL_STATES)     # P⁻ = Φ_k P Φ_kᵀ + Q_d


@numba.njit(**JIT)
def clamp_to_stop(x_hat, stop_m):
    """The touchdown bearing in the filter's model: x̂ = ±c, v̂ = 0 when it points into the stop."""
    if x_hat[0] <= -stop_m:
        x_hat[0] = -stop_m
        x_hat[1] = max(x_hat[1], 0.0)
    elif x_hat[0] >= stop_m:
        x_hat[0] = stop_m
        x_hat[1] = min(x_hat[1], 0.0)


@numba.njit(**JIT)
def predict_thrust(x_hat, P, A, B, i, Q, prediction, work_x, work_P):
    """One prediction of a thrust filter with the measured coil current i [A]: extended
    (module docstring) or the fixed (Φ, B_d) = (A, B) of ``kalman.predict``, then the stop if known."""
    if prediction.extended:
        extended_prediction(x_hat, P, i, Q, prediction, work_P)
    else:
        predict(x_hat, P, A, B, i, Q, work_x, work_P)
    clamp_to_stop(x_hat, prediction.stop_m)


def history_model(kalman_filter: KalmanFilter, prediction: ThrustPrediction, title: str, states,
                  measurements) -> FilterModel:
    """The filter as ``filter_history`` replays it: the fixed linear model when it is one, else
    ``predict_thrust`` as its propagation, giving each sample's Φ_k."""
    T = prediction.sample_time_s
    if not prediction.extended and not np.isfinite(prediction.stop_m):
        return FilterModel.of_filter(kalman_filter, title, T, states, measurements)
    n = kalman_filter.dim_x
    A, B, Q = kalman_filter.A, kalman_filter.B, kalman_filter.Q
    own = prediction._replace(transition=np.zeros((STATE_SIZE, STATE_SIZE)))   # not the loop's work array

    def history_step(x_post, P_post, u, q_scale, dt):
        x, P = np.zeros(STATE_SIZE), np.zeros((STATE_SIZE, STATE_SIZE))
        x[:n], P[:n, :n] = x_post, P_post
        predict_thrust(x, P, A, B, float(u[0]), Q * q_scale, own, np.empty(STATE_SIZE),
                       np.empty((STATE_SIZE, STATE_SIZE)))
        Phi = own.transition if prediction.extended else A
        return x[:n], P[:n, :n], Phi[:n, :n].copy(), Q[:n, :n] * q_scale
    return FilterModel.propagated(title, T, 1, kalman_filter.C[:, :n], Q[:n, :n], kalman_filter.R_diag, states,
                                  measurements, history_step,
                                  EXTENDED_PREDICTION_LATEX if prediction.extended else CLAMPED_PREDICTION_LATEX)
