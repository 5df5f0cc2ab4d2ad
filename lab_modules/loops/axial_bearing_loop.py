"""Closed loop of the axial bearing of paper 002 (Fig. 1, Fig. 4, Fig. 8), compiled.

Plant: eq. 1-2 (vertical axis, m ẍ = F_Magnet(i, x) + F_St - m g), integrated by
RK4 (two sub-steps per sample) with the coil current held over the sample; the
sensor is the first-order lag of eq. 18 (T_Sen, K_Sen), its output carries white
noise of variance var_sensor [V²].  Amplifier: ideal current source of gain 1 A/V
with white current noise of variance var_process [A²] per sample (the "process
noise" of §E; the filter's Q = var_process·b bᵀ models exactly this), limited to
|i| ≤ i0 (a coil current cannot be negative).

Controller (not in the paper; a lab choice): PID on the measured position, x_M / K_Sen, with
derivative on the measurement (filtered, τ_D), gravity feed-forward m g / k_i(centre), and a
first-order reference filter so that the moves between operating points do not saturate the amplifier.

Four filters run side by side on the same measurements and currents (they do not
act on the loop): 0 fixed k_i, k_s (centre values, §B); 1 scheduled by the FBFNN
(§D, Fig. 8); 2 scheduled by the exact no-intercept LSM at the operating point;
3 EKF with the force law eq. 1.  The operating point for scheduling is
(commanded current, filter's own position estimate).

The SISO ADALINE (eq. 24) identifies k_Magnet from (i, measured x) and a measured
magnet force with white noise of σ_F (lab choice: the paper's target is the
MISO ADALINE's force estimate).

The kernel takes named bundles: ``Schedule``, ``AxialPID``, ``FilterBank``, ``Identification``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import control
import numpy as np
import scipy.linalg
from numba import njit

from lab_modules import analysis
from lab_modules.estimators import scheduled_kalman
from lab_modules.estimators.adaline import siso_step
from lab_modules.estimators.filter_history import FilterModel, FilterTape
from lab_modules.estimators.fuzzy_basis_network import CENTRES, evaluate
from lab_modules.estimators.kalman import correction
from lab_modules.estimators.scheduled_kalman import (
    BIAS,
    GAP,
    GRAVITY,
    K_MAGNET,
    MASS,
    N_STATES,
    SAMPLE,
    SENSOR_GAIN,
    SENSOR_LAG,
    VAR_SENSOR,
    correct,
    model_matrices,
    physics_vector,
    predict_exact_force,
    predict_linear,
    process_noise,
)
from lab_modules.estimators.stiffness_identification import PAPER_STENCIL_A, PAPER_STENCIL_M, lsm_factors_at
from lab_modules.plants.axial_bearing import AXIAL, force_shape, magnet_force, tangent_factors

SAMPLE_TIME_S = 100e-6              # not in the paper (lab choice, §E gives none)
SENSOR_LAG_S = 100e-6               # T_Sen, not in the paper
SENSOR_GAIN_V_PER_M = 1000.0        # K_Sen = 1 V/mm, not in the paper
VAR_PROCESS_A2 = 8e-5               # §E "process noise variance 8e-5 V", read as A² at 1 A/V
VAR_SENSOR_V2 = 8.3e-5              # §E "measurement noise variance 8.3e-5 V/mm", read as V² at 1 V/mm
Q_FORCE_N2 = 1e-2                   # q_F, "experimentally initialized" in the paper; lab choice
TOUCHDOWN_M = 1.5e-3                # retainer bearing at 0.5 mm from the magnets (lab choice)
RK4_SUBSTEPS = 2
FILTERS = ("fixed", "fbfnn", "lsm", "ekf")
N_FILTERS = len(FILTERS)
FILTER_NAMES = {"fixed": "fixed k_i, k_s (§B)", "fbfnn": "k_i, k_s scheduled by the FBFNN (§D)",
                "lsm": "k_i, k_s scheduled by the LSM", "ekf": "EKF with the force law eq. 1"}

COLUMNS = (
    "x_true_m", "x_measured_m", "x_reference_m", "current_a", "magnet_force_n", "disturbance_n",
    *[f"{f}_{q}" for f in FILTERS for q in ("x_m", "x_sigma_m", "force_n", "force_sigma_n")],
    "ki_tangent_n_per_a", "ks_tangent_n_per_m", "ki_fbfnn_n_per_a", "ks_fbfnn_n_per_m",
    "ki_lsm_n_per_a", "ks_lsm_n_per_m", "k_magnet_estimate", "k_magnet_true", "velocity_true_m_per_s",
    "current_command_a",
)
COLUMN = {name: j + 1 for j, name in enumerate(COLUMNS)}      # row index 0 is time


def column(trace: np.ndarray, name: str) -> np.ndarray:
    return trace[:, COLUMN[name]]


@dataclass(frozen=True)
class Segment:
    """From ``start_s`` on: position reference, disturbance force F_St and the plant's k_Magnet factor."""

    start_s: float
    reference_m: float
    disturbance_n: float
    k_magnet_factor: float = 1.0


@dataclass(frozen=True)
class LoopSetup:
    segments: tuple[Segment, ...]
    period_s: float                      # the schedule repeats (live view); metrics run one period
    load_ramp_s: float                   # a new disturbance force ramps in linearly over this time
    fbfnn_ki: tuple[np.ndarray, np.ndarray]       # (weights [N/A], widths)
    fbfnn_ks: tuple[np.ndarray, np.ndarray]       # (weights [N/m], widths)
    gravity: float = AXIAL.gravity_m_per_s2
    var_process_a2: float = VAR_PROCESS_A2
    var_sensor_v2: float = VAR_SENSOR_V2
    q_force_n2: float = Q_FORCE_N2
    sensor_lag_s: float = SENSOR_LAG_S
    feedback: str = "fbfnn"                   # "measured" or one of FILTERS
    proportional_a_per_m: float = 4.0e3       # K_P = 4 A/mm
    integral_time_s: float = 0.02
    derivative_a_s_per_m: float = 18.0        # K_D
    derivative_filter_s: float = 1e-3         # only with measured feedback
    reference_filter_s: float = 0.01
    adaline_rate: float = 0.0174              # η in (mm²/A²)²·A²/(N·mm²)... see adaline_rate_note
    adaline_initial: float = 5.0              # k̂_Magnet at the start [N·mm²/A²]
    force_noise_n: float = 0.0                # σ of the measured magnet force for the ADALINE
    plant_force_walk_n2: float = 0.0          # a random-walk part of F_St in the plant (variance per sample)
    k_magnet: float = AXIAL.k_magnet_n_m2_per_a2
    filter_k_magnet: float = AXIAL.k_magnet_n_m2_per_a2   # what the filters' models assume
    stencil_a: float = PAPER_STENCIL_A
    stencil_m: float = PAPER_STENCIL_M

    def physics(self) -> np.ndarray:
        return physics_vector(AXIAL.mass_kg, SAMPLE_TIME_S, self.sensor_lag_s, SENSOR_GAIN_V_PER_M,
                              self.gravity, self.var_process_a2, self.q_force_n2, self.var_sensor_v2,
                              self.filter_k_magnet, AXIAL.nominal_gap_m, AXIAL.bias_current_a)

    def schedule(self) -> np.ndarray:
        return np.array([[s.start_s, s.reference_m, s.disturbance_n, s.k_magnet_factor] for s in self.segments])

    def controller(self) -> AxialPID:
        k_i, _ = AXIAL.centre_factors()
        return AxialPID(proportional_a_per_m=self.proportional_a_per_m, integral_time_s=self.integral_time_s,
                        derivative_a_s_per_m=self.derivative_a_s_per_m, derivative_filter_s=self.derivative_filter_s,
                        reference_filter_s=self.reference_filter_s,
                        feedforward_a=AXIAL.mass_kg * self.gravity / k_i,
                        feedback=-1 if self.feedback == "measured" else FILTERS.index(self.feedback))


def scheduled_factors(setup: LoopSetup) -> dict:
    """Per filter of ``FILTERS``: (i [A], x̂ [m]) -> (k_i [N/A], k_s [N/m]) of its model as ``run`` schedules
    it (the EKF's: the tangent factors of its force law, eq. 3-4)."""
    k_magnet, gap, bias = setup.filter_k_magnet, AXIAL.nominal_gap_m, AXIAL.bias_current_a
    return {"fixed": lambda i, x: (4 * k_magnet * bias / gap**2, 4 * k_magnet * bias**2 / gap**3),
            "fbfnn": lambda i, x: (evaluate(i, x, CENTRES, *setup.fbfnn_ki), evaluate(i, x, CENTRES, *setup.fbfnn_ks)),
            "lsm": lambda i, x: lsm_factors_at(i, x, setup.stencil_a, setup.stencil_m, k_magnet, gap, bias),
            "ekf": lambda i, x: tangent_factors(i, x, k_magnet, gap, bias)}


# state vector layout
(S_T, S_X, S_V, S_XM, S_INTEGRAL, S_DERIV, S_PREV_MEAS, S_REF, S_ADALINE, S_STOPPED, S_CURRENT, S_WALK) = range(12)
N_LOOP_STATE = 12


class Schedule(NamedTuple):
    """The plant's programme: segments that repeat with a period, a load that ramps in."""

    segments: np.ndarray      # (n, 4) per segment: start [s], position reference [m], disturbance F_St [N],
    #                           factor on k_Magnet [-] (``LoopSetup.schedule``)
    period_s: float           # the schedule repeats after this time [s]
    load_ramp_s: float        # a new disturbance force ramps in linearly over this time [s]
    k_magnet: float           # the plant's k_Magnet before the segments' factor [N m²/A²]


class AxialPID(NamedTuple):
    """The lab's PID (module docstring), SI units."""

    proportional_a_per_m: float   # K_P [A/m]
    integral_time_s: float        # T_I [s]
    derivative_a_s_per_m: float   # K_D [A s/m]
    derivative_filter_s: float    # τ_D of the derivative of the measured position [s]
    reference_filter_s: float     # time constant of the first-order reference filter [s]
    feedforward_a: float          # gravity feed-forward m g / k_i(centre) [A]
    feedback: int                 # -1: the measured position; else the index in ``FILTERS`` fed back


class FilterBank(NamedTuple):
    """The four filters of ``FILTERS``, side by side, states (x [m], v [m/s], F_St [N], x_M [V])."""

    z: np.ndarray   # (N_FILTERS, 4) estimates, in place [m, m/s, N, V]
    P: np.ndarray   # (N_FILTERS, 4, 4) error covariances, in place [state unit x state unit]


class Identification(NamedTuple):
    """The online identification of the force factors: FBFNN (§D), exact LSM, SISO ADALINE (eq. 24)."""

    centres: np.ndarray       # (n_nodes, 2) FBFNN node centres (i / 1.5 A, x / 0.5 mm) [-]
    ki_weights: np.ndarray    # (n_nodes,) FBFNN weights of k_i [N/A]
    ki_widths: np.ndarray     # (n_nodes,) their widths [-]
    ks_weights: np.ndarray    # (n_nodes,) FBFNN weights of k_s [N/m]
    ks_widths: np.ndarray     # (n_nodes,) their widths [-]
    stencil_a: float          # LSM stencil in the current [A]
    stencil_m: float          # LSM stencil in the position [m]
    adaline_rate: float       # η of eq. 24 in the paper's units (φ [A²/mm²], k_Magnet [N mm²/A²])


class AxialRig(NamedTuple):
    """The rig's constants the plant's rates need (``plant_rates``)."""

    mass_kg: float                # rotor mass m [kg]
    gravity_m_per_s2: float       # g [m/s²]
    gap_m: float                  # nominal air gap s0 [m]
    bias_current_a: float         # bias current i0 [A]
    sensor_lag_s: float           # T_Sen of eq. 18 [s]
    sensor_gain_v_per_m: float    # K_Sen of eq. 18 [V/m]


@njit(cache=True, nogil=True)
def plant_rates(x, v, xm, current, load, k_magnet, rig):
    """Rates of x [m], v [m/s] and the sensor output x_M [V] (eq. 1-2, 18) for the plant's k_Magnet."""
    accel = (magnet_force(current, x, k_magnet, rig.gap_m, rig.bias_current_a) + load) / rig.mass_kg - rig.gravity_m_per_s2
    return v, accel, (rig.sensor_gain_v_per_m * x - xm) / rig.sensor_lag_s


@njit(cache=True, nogil=True)
def plant_sample(x, v, xm, current, load, k_magnet, rig, sample_time_s):
    """(x [m], v [m/s], x_M [V]) one sample later: RK4 in ``RK4_SUBSTEPS`` sub-steps, current and load held."""
    h = sample_time_s / RK4_SUBSTEPS
    for _ in range(RK4_SUBSTEPS):
        d1 = plant_rates(x, v, xm, current, load, k_magnet, rig)
        d2 = plant_rates(x + 0.5 * h * d1[0], v + 0.5 * h * d1[1], xm + 0.5 * h * d1[2], current, load, k_magnet, rig)
        d3 = plant_rates(x + 0.5 * h * d2[0], v + 0.5 * h * d2[1], xm + 0.5 * h * d2[2], current, load, k_magnet, rig)
        d4 = plant_rates(x + h * d3[0], v + h * d3[1], xm + h * d3[2], current, load, k_magnet, rig)
        x, v, xm = (x + h / 6 * (d1[0] + 2 * d2[0] + 2 * d3[0] + d4[0]),
                     v + h / 6 * (d1[1] + 2 * d2[1] + 2 * d3[1] + d4[1]), xm + h / 6 * (d1[2] + 2 * d2[2] + 2 * d3[2] + d4[2]))
    return x, v, xm


@njit(cache=True, nogil=True)
def run(n_steps, state, physics, schedule, pid, filters, identification, noise, out):
    """Advance ``n_steps`` samples; writes rows (time, *COLUMNS) into ``out``; returns the rows written
    (fewer after a touchdown).

    state : (N_LOOP_STATE,) the loop's state (indices ``S_T`` ...), in place;
    physics : ``scheduled_kalman.physics_vector`` of the filters' model (indices ``MASS`` ...);
    schedule, pid, filters (in place), identification : ``Schedule``, ``AxialPID``, ``FilterBank``, ``Identification``;
    noise : (n_steps, 4) draws: sensor [V], current [A], measured force [N], force random walk [N].

    The filters' steps are ``scheduled_kalman``'s written-out 4×4 kernels (no BLAS calls, no
    temporaries): a sample costs about 1 µs."""
    # every field read once, before the loop (a bundle's array read per sample costs a reference count)
    segments, period, load_ramp = schedule.segments, schedule.period_s, schedule.load_ramp_s
    k_magnet_nominal, filter_z, filter_P = schedule.k_magnet, filters.z, filters.P
    centres, fbf_ki_w, fbf_ki_s = identification.centres, identification.ki_weights, identification.ki_widths
    fbf_ks_w, fbf_ks_s = identification.ks_weights, identification.ks_widths
    stencil_a, stencil_m, adaline_rate = identification.stencil_a, identification.stencil_m, identification.adaline_rate
    T, sensor_gain, gap, bias = physics[SAMPLE], physics[SENSOR_GAIN], physics[GAP], physics[BIAS]
    rig = AxialRig(mass_kg=physics[MASS], gravity_m_per_s2=physics[GRAVITY], gap_m=gap, bias_current_a=bias,
                   sensor_lag_s=physics[SENSOR_LAG], sensor_gain_v_per_m=sensor_gain)
    A = np.zeros((N_STATES, N_STATES))
    B = np.zeros((N_STATES, 2))
    Q = np.zeros((N_STATES, N_STATES))
    A_fixed = np.zeros((N_STATES, N_STATES))
    B_fixed = np.zeros((N_STATES, 2))
    Q_fixed = np.zeros((N_STATES, N_STATES))
    ki0 = 4 * physics[K_MAGNET] * bias / gap**2
    ks0 = 4 * physics[K_MAGNET] * bias**2 / gap**3
    model_matrices(ki0, ks0, physics, A_fixed, B_fixed)
    process_noise(physics, B_fixed, Q_fixed)
    kp, ti, kd = pid.proportional_a_per_m, pid.integral_time_s, pid.derivative_a_s_per_m
    tf, tr, i_ff, feedback = pid.derivative_filter_s, pid.reference_filter_s, pid.feedforward_a, pid.feedback
    for k in range(n_steps):
        if state[S_STOPPED] > 0:
            return k
        t = state[S_T]
        # schedule (repeats with the period)
        tau = t % period
        seg = 0
        for j in range(segments.shape[0]):
            if tau >= segments[j, 0] - 1e-12:
                seg = j
        reference, load, k_factor = segments[seg, 1], segments[seg, 2], segments[seg, 3]
        if seg > 0:
            previous = segments[seg - 1, 2]
        elif t >= period:
            previous = segments[segments.shape[0] - 1, 2]     # the schedule wraps round
        else:
            previous = load
        if load_ramp > 0.0 and tau - segments[seg, 0] < load_ramp:
            load = previous + (load - previous) * (tau - segments[seg, 0]) / load_ramp
        k_magnet = k_magnet_nominal * k_factor
        load += state[S_WALK]
        state[S_WALK] += noise[k, 3]
        x, v, xm = state[S_X], state[S_V], state[S_XM]
        y = xm + noise[k, 0]
        x_meas = y / sensor_gain
        # filters: correction with y(k)
        for f in range(4):
            correct(filter_z[f], filter_P[f], y, physics[VAR_SENSOR])
        # controller: PID on the chosen position (derivative from the filter's velocity)
        state[S_REF] += (reference - state[S_REF]) * T / tr
        if feedback < 0:
            position = x_meas
            derivative = (tf * state[S_DERIV] + (x_meas - state[S_PREV_MEAS])) / (tf + T)
            if t == 0.0:
                derivative = 0.0
            state[S_DERIV] = derivative
            state[S_PREV_MEAS] = x_meas
        else:
            position = filter_z[feedback][0]
            derivative = filter_z[feedback][1]
        error = state[S_REF] - position
        state[S_INTEGRAL] += error * T
        command = i_ff + kp * (error + state[S_INTEGRAL] / ti) - kd * derivative
        if command > bias:
            command = bias
            state[S_INTEGRAL] -= error * T          # anti-windup
        elif command < -bias:
            command = -bias
            state[S_INTEGRAL] -= error * T
        current = command + noise[k, 1]
        if current > bias:
            current = bias
        elif current < -bias:
            current = -bias
        # ADALINE (SISO, paper units: A, mm, N)
        force_true = magnet_force(current, x, k_magnet, gap, bias)
        phi_mm = force_shape(current, position, gap, bias) * 1e-6
        state[S_ADALINE] = siso_step(state[S_ADALINE], phi_mm, force_true + noise[k, 2], adaline_rate)
        # record (a posteriori estimates at k)
        row = out[k]
        row[0] = t
        row[1] = x
        row[2] = x_meas
        row[3] = state[S_REF]
        row[4] = current
        row[5] = force_true
        row[6] = load
        for f in range(4):
            row[7 + 4 * f] = filter_z[f][0]
            row[8 + 4 * f] = np.sqrt(max(filter_P[f][0, 0], 0.0))
            row[9 + 4 * f] = filter_z[f][2]
            row[10 + 4 * f] = np.sqrt(max(filter_P[f][2, 2], 0.0))
        kit, kst = tangent_factors(current, x, k_magnet, gap, bias)
        row[23] = kit
        row[24] = kst
        # filters: prediction with the commanded current
        # 0 fixed
        predict_linear(filter_z[0], filter_P[0], A_fixed, B_fixed, Q_fixed, command)
        # 1 FBFNN-scheduled
        ki_f = evaluate(command, filter_z[1][0], centres, fbf_ki_w, fbf_ki_s)
        ks_f = evaluate(command, filter_z[1][0], centres, fbf_ks_w, fbf_ks_s)
        row[25] = ki_f
        row[26] = ks_f
        model_matrices(ki_f, ks_f, physics, A, B)
        process_noise(physics, B, Q)
        predict_linear(filter_z[1], filter_P[1], A, B, Q, command)
        # 2 exact LSM
        ki_l, ks_l = lsm_factors_at(command, filter_z[2][0], stencil_a, stencil_m, physics[K_MAGNET], gap, bias)
        row[27] = ki_l
        row[28] = ks_l
        model_matrices(ki_l, ks_l, physics, A, B)
        process_noise(physics, B, Q)
        predict_linear(filter_z[2], filter_P[2], A, B, Q, command)
        # 3 EKF, force law eq. 1
        predict_exact_force(filter_z[3], filter_P[3], physics, command, A, B, Q)
        row[29], row[30], row[31], row[32] = state[S_ADALINE], k_magnet * 1e6, v, command
        # plant: RK4 over the sample, current held
        x, v, xm = plant_sample(x, v, xm, current, load, k_magnet, rig, T)
        state[S_X], state[S_V], state[S_XM] = x, v, xm
        state[S_CURRENT] = current
        state[S_T] = t + T
        if not np.isfinite(x) or abs(x) >= TOUCHDOWN_M:
            state[S_STOPPED] = 1.0
            return k + 1
    return n_steps


class LoopSimulation:
    """The compiled loop, advanced block by block (the app's ``Simulation``)."""

    sample_time_s = SAMPLE_TIME_S
    columns = COLUMNS

    def __init__(self, setup: LoopSetup, seed: int = 0):
        self.setup = setup
        self.rng = np.random.default_rng(seed)
        self.state = np.zeros(N_LOOP_STATE)
        self.state[S_ADALINE] = setup.adaline_initial
        self.filter_z = np.zeros((N_FILTERS, N_STATES))
        P0 = np.diag([20e-6, 1e-3, 1.0, 20e-3]) ** 2
        self.filter_P = np.repeat(P0[None], N_FILTERS, axis=0)
        self._arrays(setup)

    def _arrays(self, setup: LoopSetup) -> None:
        self.physics = setup.physics()
        self.schedule = Schedule(segments=setup.schedule(), period_s=setup.period_s, load_ramp_s=setup.load_ramp_s,
                                 k_magnet=setup.k_magnet)
        self.pid = setup.controller()
        ki_weights, ki_widths, ks_weights, ks_widths = (np.ascontiguousarray(a, dtype=np.float64)
                                                        for a in (*setup.fbfnn_ki, *setup.fbfnn_ks))
        self.identification = Identification(centres=CENTRES, ki_weights=ki_weights, ki_widths=ki_widths,
                                             ks_weights=ks_weights, ks_widths=ks_widths, stencil_a=setup.stencil_a,
                                             stencil_m=setup.stencil_m, adaline_rate=setup.adaline_rate)
        shown = "fbfnn" if setup.feedback == "measured" else setup.feedback   # the filter ``filter_state`` shows
        self.shown, sk = FILTERS.index(shown), scheduled_kalman
        self.tape = FilterTape(FilterModel.propagated(
            f"Kalman filter of the axial bearing (paper 002): {FILTER_NAMES[shown]}", SAMPLE_TIME_S, 1, sk.H,
            np.full((N_STATES, N_STATES), np.nan), [setup.var_sensor_v2], sk.STATES, sk.MEASUREMENTS,
            sk.propagation(self.physics, None if shown == "ekf" else scheduled_factors(setup)[shown]), sk.PREDICTION_LATEX))

    def retuned(self, setup: LoopSetup) -> LoopSimulation:
        """The same running loop with new settings (state, filters and noise stream kept)."""
        self.setup = setup
        self._arrays(setup)
        return self

    def advance(self, n_steps: int) -> np.ndarray:
        noise = np.column_stack([
            self.rng.normal(0.0, np.sqrt(self.setup.var_sensor_v2), n_steps),
            self.rng.normal(0.0, np.sqrt(self.setup.var_process_a2), n_steps),
            self.rng.normal(0.0, self.setup.force_noise_n, n_steps) if self.setup.force_noise_n > 0
            else np.zeros(n_steps),
            self.rng.normal(0.0, np.sqrt(self.setup.plant_force_walk_n2), n_steps)
            if self.setup.plant_force_walk_n2 > 0 else np.zeros(n_steps)])
        out = np.empty((n_steps, 1 + len(COLUMNS)))
        # a single step (the inspector's) keeps the filters' priors and the measurement for ``filter_state``
        priors, first_sample = (self.filter_z.copy(), self.filter_P.copy()), round(self.state[S_T] / SAMPLE_TIME_S)
        self._last_correction = (*priors, self.state[S_XM] + noise[0, 0], self.state[S_T]) if n_steps == 1 else None
        n = run(n_steps, self.state, self.physics, self.schedule, self.pid,
                FilterBank(z=self.filter_z, P=self.filter_P), self.identification, noise, out)
        rows = out[:n]
        y = column(rows, "x_measured_m") * SENSOR_GAIN_V_PER_M            # eq. 21: y = x_M + n
        truth = np.column_stack([column(rows, "x_true_m"), column(rows, "velocity_true_m_per_s"),
                                 column(rows, "disturbance_n"), y - noise[:n, 0]])
        self.tape.record(first_sample, priors[0][self.shown], priors[1][self.shown], rows[:, 0],
                         column(rows, "current_command_a"), y, truth)
        return rows

    def filter_tape(self) -> FilterTape:
        """The record of the shown filter's inputs since the last launch or retune (``estimators.filter_history``)."""
        return self.tape

    def filter_state(self) -> dict | None:
        """The filter the controller acts on (the FBFNN-scheduled one under measured feedback)
        at the sample of the last advance(1): corrected z and P, gain K, innovation and √S
        (eq. 11-13, H = (0, 0, 0, 1), R = var_sensor)."""
        if getattr(self, "_last_correction", None) is None:
            return None
        z_prior, P_prior, y, time_s = self._last_correction
        model = self.tape.model
        step = correction(z_prior[self.shown], P_prior[self.shown], model.H, [self.setup.var_sensor_v2], [y])
        return {"title": model.title, "time_s": float(time_s), "x": step["x"], "P": step["P"], "states": model.states,
                "measurements": model.measurements, "K": step["K"], "innovation": step["innovation"],
                "innovation_sigma": np.sqrt(np.diag(step["S"]))}

    def status_message(self) -> str:
        if self.state[S_STOPPED] > 0:
            return f"Touchdown: the rotor reached the retainer bearing at ±{TOUCHDOWN_M * 1e3:g} mm."
        return ""


# -- the loop linearised at the centre, broken at the plant input (margins, |S|max) ---------------
def loop_at_plant_input(setup: LoopSetup) -> control.StateSpace:
    """Open loop L broken at the current command (S = 1 / (1 + L)), linearised at rest at the
    centre (x = 0, no load, the current that holds the weight): plant eq. 1-2 with its tangent
    factors there (eq. 3-4) and the sensor lag eq. 18, by a zero-order hold (current held, as the
    kernel's RK4); the PID as ``run`` computes it, on the measurement (filtered difference) or on
    the chosen filter's position and velocity.  That filter is its steady state (eq. 9-13, scipy's
    Riccati solver) on the model ``model_matrices`` builds with its factors at the operating point:
    centre values (fixed), the FBFNN's or the exact LSM's there, or the tangent ones (EKF); the
    scheduling's own derivatives are left out.  Amplifier noise and limits are not in it."""
    physics = setup.physics()
    T, m, gap, bias = physics[SAMPLE], AXIAL.mass_kg, physics[GAP], physics[BIAS]
    pid = setup.controller()
    kp, ti, kd, tf = pid.proportional_a_per_m, pid.integral_time_s, pid.derivative_a_s_per_m, pid.derivative_filter_s
    current = pid.feedforward_a
    k_i, k_s = tangent_factors(current, 0.0, setup.k_magnet, gap, bias)
    F = np.array([[0.0, 1.0, 0.0], [k_s / m, 0.0, 0.0],
                  [SENSOR_GAIN_V_PER_M / setup.sensor_lag_s, 0.0, -1.0 / setup.sensor_lag_s]])
    plant = control.c2d(control.ss(F, [[0.0], [k_i / m], [0.0]], [[0.0, 0.0, 1.0]], 0.0), T, "zoh")
    if setup.feedback == "measured":
        def step(c, y):                          # c = (integral, derivative, previous position)
            position = y[0] / SENSOR_GAIN_V_PER_M
            derivative = (tf * c[1] + position - c[2]) / (tf + T)
            integral = c[0] - position * T
            return np.array([integral, derivative, position]), np.array([kp * (-position + integral / ti)
                                                                         - kd * derivative])
        return analysis.loop_at_plant_input(plant, analysis.state_space_from_step(step, 3, 1, T))
    factors = scheduled_factors(setup)[setup.feedback](current, 0.0)
    A, B, Q = np.zeros((N_STATES, N_STATES)), np.zeros((N_STATES, 2)), np.zeros((N_STATES, N_STATES))
    model_matrices(float(factors[0]), float(factors[1]), physics, A, B)
    process_noise(physics, B, Q)
    H = np.zeros((1, N_STATES))
    H[0, 3] = 1.0
    P = scipy.linalg.solve_discrete_are(A.T, H.T, Q, np.array([[setup.var_sensor_v2]]))
    K = (P @ H.T / (H @ P @ H.T + setup.var_sensor_v2))[:, 0]

    def step(c, y):                              # c = (filter prediction z_p (4), integral)
        z = c[:N_STATES] + K * (y[0] - c[3])
        integral = c[N_STATES] - z[0] * T
        command = kp * (-z[0] + integral / ti) - kd * z[1]
        return np.append(A @ z + B[:, 0] * command, integral), np.array([command])
    return analysis.loop_at_plant_input(plant, analysis.state_space_from_step(step, N_STATES + 1, 1, T))
