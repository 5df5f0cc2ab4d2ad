"""What several exercises build from the same sliders, and how they name poles and report them.

The controller sliders pid_gain, integral_time_ms, derivative_time_ms and
derivative_filter_us are the paper's PID (paper 000, §IV), defined once in
``_radial_axis_controls`` for the exercises that run it.
"""

from __future__ import annotations

from functools import lru_cache

import control
import numpy as np

from lab_modules import analysis
from lab_modules.controllers.pid import pid
from lab_modules.exercises._radial_axis_controls import PAPER_PID, PLANT_NOISE, SENSOR_LAG
from lab_modules.loops.radial_axis_experiment import AxisSetup
from lab_modules.parameters import in_si
from lab_modules.plants.radial_bearing import RIG

#: ``controllers.pid`` remembered per setting: its Tustin discretisation takes
#: milliseconds, most slider moves leave the gains alone, and the analyses
#: build the same PID for several runs.
_cached_pid = lru_cache(maxsize=128)(pid)


def pid_from_values(values: dict, gain_factor: float = 1.0) -> control.StateSpace:
    """The PID of the controller sliders at the rig's sample time, its gain K times ``gain_factor``."""
    si = in_si(PAPER_PID, values)
    return _cached_pid(values["pid_gain"] * gain_factor, si["integral_time_ms"],
                       si["derivative_time_ms"], si["derivative_filter_us"],
                       RIG.sample_time_s)


def ekf_loop_fields(values: dict) -> dict:
    """The ``radial_axis_ekf_loop.EKFLoopSetup`` fields that the EKF exercises read from the same
    sliders: the PID and its feedback source, the measurement variances R (eq. 16)
    and the plant's noise."""
    return {"controller": pid_from_values(values),
            "use_estimate": values["feedback"] == "estimated",
            "filter_R_diag": np.array([values["filter_r_position"], values["filter_r_current"]]),
            "sensor_noise_m": in_si(PLANT_NOISE, values)["sensor_noise_um"],
            "current_noise_a": values["current_noise_a"],
            "process_force_n": values["disturbance_force_n"]}


def linear_axis(values: dict) -> AxisSetup:
    """The linear loop the EKF exercises' pole maps show (issue 11, defect 9): the PID on the rig's
    linear model (eq. 3-4) and the EKF's physical part (x, v, i) as a steady-state Kalman filter with
    the same q_22, q_33 and R, k_i and k_x held at their rated values.  The parameter states are random
    walks whose error poles sit near s = 0 and move with the excitation: not shown."""
    return AxisSetup(controller=pid_from_values(values), use_estimate=values["feedback"] == "estimated",
                     sensor_lag_s=SENSOR_LAG.si(values), filter_q_velocity=values["filter_q_velocity"],
                     filter_q_current=values["filter_q_current"], filter_r_position=values["filter_r_position"],
                     filter_r_current=values["filter_r_current"])


def pairs(values) -> list[list[float]]:
    """Complex numbers as [re, im] pairs for JSON."""
    return [[float(v.real), float(v.imag)] for v in np.sort_complex(np.asarray(values, dtype=complex))]


# -- pole names for the pole map (``Exercise.mode_names``) ----------------------------------
def nearest_names(poles_s, named: list[tuple[complex, str]], tolerance: float = 1e-6) -> list[str | None]:
    """For each pole [rad/s] the name of the nearest named pole (or its conjugate) within
    ``tolerance`` × |s|; None where no named pole is that close."""
    out = []
    for p in np.asarray(poles_s, dtype=complex):
        distances = [min(abs(p - q), abs(p - np.conj(q))) for q, _ in named]
        k = int(np.argmin(distances)) if distances else -1
        out.append(named[k][1] if k >= 0 and distances[k] <= tolerance * max(abs(p), 1.0) else None)
    return out


def magnet_plant_names(poles_s, A, body: str, lags: tuple[str, ...]) -> list[str | None]:
    """Names of an open-loop magnet plant's poles [rad/s].  Its states are a position, a
    velocity and first-order lags (coil current, sensor) driven by them but not driving back
    into each other, so the state matrix ``A`` is block triangular: the magnet's negative
    stiffness gives ±√A[1,0] (the unstable pole and its stable mirror), each lag its own
    diagonal entry (``lags`` names them in state order)."""
    A = np.asarray(A, dtype=float)
    a = float(np.sqrt(A[1, 0]))
    named = [(complex(a), f"{body} position (unstable magnet pole)"),
             (complex(-a), f"{body} position (stable mirror of the magnet pole)")]
    named += [(complex(A[2 + k, 2 + k]), name) for k, name in enumerate(lags[:A.shape[0] - 2])]
    return nearest_names(poles_s, named)


#: the lags of the radial bearing axis (paper 000 eq. 4 and 12), in ``RIG.continuous_model``'s state order
AXIS_LAGS = ("coil current (amplifier lag T_a)", "position sensor lag T_mx")
#: the maglev ball's coil (paper 004 eq. 2.8: R/L), in ``TABLE_3_1.linear_model``'s state order
MAGLEV_LAGS = ("coil current (R/L)",)


def axis_plant_names(poles_s) -> list[str | None]:
    """Names of the radial axis's open-loop plant poles (``RIG.continuous_model``): its only
    state beyond x, v and i is the sensor lag x_d, so the one real pole left is that lag's."""
    names = magnet_plant_names(poles_s, RIG.continuous_model(0.0).A, "rotor", AXIS_LAGS[:1])
    return [AXIS_LAGS[1] if name is None and abs(p.imag) == 0 and p.real < 0 else name
            for p, name in zip(np.asarray(poles_s, dtype=complex), names)]


#: The radial axis's states with units and the physics each belongs to (paper 000: x, v from
#: eq. 1 and 3, the coil current i from eq. 4 (amplifier lag T_a), the sensor's output x_d from
#: eq. 12-13), in ``RIG.continuous_model``'s state order; what ``analysis.name_modes`` names by.
AXIS_STATES = (("x [m]", "rotor position/velocity (suspension mode)"),
               ("v [m/s]", "rotor position/velocity (suspension mode)"),
               ("i [A]", "coil current"),
               ("x_d [m]", "position sensor lag"))
#: The estimation errors x̂ − x of the same states (a filter's error dynamics, eq. 2)
AXIS_ERROR_STATES = (("x error [m]", "position/velocity estimate error"),
                     ("v error [m/s]", "position/velocity estimate error"),
                     ("i error [A]", "coil current estimate error"),
                     ("x_d error [m]", "sensor-lag estimate error"))
#: The integral of the position error that paper 000's LQG regulator adds (§IV, eq. 19)
INTEGRAL_STATE = ("ξ = ∫(r − x) dt [m s]", "LQG position integrator")


def controller_states(controller, basis) -> list[tuple[str, str]]:
    """Names of a discrete controller's states in its modal ``basis`` (``analysis.modal_basis``):
    a pole at z = 1 is the PID integrator (paper 000 §IV: 1/(T_I s)), any other the derivative
    filter (τ) or, for other controllers, a compensator lag."""
    A = np.asarray(controller.A, dtype=float)
    out = []
    for column in basis.T:
        rayleigh = float(column @ A @ column / (column @ column))
        integrator = abs(rayleigh - 1.0) < 1e-6
        out.append(("PID integrator [V s]", "PID integrator") if integrator
                   else ("PID derivative filter [V]", "PID derivative filter"))
    return out


def axis_loop_modes(axis, gain_factor: float = 1.0) -> tuple[np.ndarray, list[tuple[str, str]]]:
    """The state matrix of an ``AxisSetup``'s closed loop (``loop_matrix``) in physical
    coordinates, with its state names (``analysis.name_modes``): the plant's states, the
    controller's modal states (integrator, derivative filter) and, when the filter is in the
    loop, its estimation error x̂ − x instead of its estimate (the separation principle then
    splits the loop's modes into control and filter-error modes)."""
    loop = axis.loop(gain_factor=gain_factor)
    A = np.asarray(loop.system.A)[loop.loop_states, loop.loop_states]
    n, nc = axis.model.nstates, axis.controller.nstates
    V = analysis.modal_basis(axis.controller.A) if nc else np.zeros((0, 0))
    size = A.shape[0]
    T = np.zeros((size, size))
    T[:n, :n] = np.eye(n)
    T[n:n + nc, n:n + nc] = V
    states = list(AXIS_STATES[:n]) + controller_states(axis.controller, V)
    if size > n + nc:                                  # the filter's estimate x_p = s + e
        T[n + nc:, :n] = np.eye(n)
        T[n + nc:, n + nc:] = np.eye(n)
        states += list(AXIS_ERROR_STATES[:n])
    return analysis.change_basis(A, T), states


def axis_mode_matrices(axis, loop_set: str, error_set: str | None = None) -> dict:
    """``Exercise.mode_matrices`` of a radial axis: its closed loop and the steady-state filter's
    error A − A K C (eq. 2), both discrete at the rig's sample time."""
    A_loop, states = axis_loop_modes(axis)
    out = {loop_set: (A_loop, states, RIG.sample_time_s)}
    if error_set is not None:
        K, _ = axis.steady_state_filter
        A, C = np.asarray(axis.model.A), np.asarray(axis.model.C)
        out[error_set] = (A - A @ K @ C, list(AXIS_ERROR_STATES[:A.shape[0]]), RIG.sample_time_s)
    return out
