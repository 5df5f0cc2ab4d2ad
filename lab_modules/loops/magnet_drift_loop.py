"""The adaptive loop of paper 002, Figs. 1 and 8, online: the magnet's k_Magnet drifts during
the run and the SISO ADALINE (eq. 24) identifies it while the filters run, compiled.

Plant, sensor, amplifier and PID as ``loops.axial_bearing_loop`` (eq. 1-2, 18; the rotor
moves between operating points under load); in addition the plant's k_Magnet changes by
``change`` (e.g. -0.1: heating, ageing) from ``start_s`` on, as a step (``ramp_s`` = 0) or
linearly over ``ramp_s``.  Four filters (``scheduled_kalman``, states x, v, F_St, x_M) watch the
same measurements:

* fixed: the centre factors of the nominal law (§B);
* offline: k_i, k_s from the FBFNN trained on the nominal law (§D, Fig. 8);
* adaptive: the same factors times k̂_Magnet / k_Magnet,nominal, k̂ from the ADALINE every
  sample (F ∝ k_Magnet in eq. 1, so are k_i and k_s);
* exact: the EKF with the force law eq. 1 and the plant's true k_Magnet at every sample.

The ADALINE's target is the adaptive filter's estimate of the magnet force (lab reconstruction
of Fig. 1's "identification" block, ``target`` = 0):

    F̂_M = (k̂ / k_0) (k_i^FBFNN i + k_s^FBFNN x̂) + F̂_St - F_applied,   φ = φ(i, x̂)      (eq. 1, 24)

the filter's force balance less the load the experiment applies (the paper identifies without a
disturbance force, §E); ``target`` = 1 uses a force sensor instead (the true magnet force plus
white noise σ_F).  The regressor φ and k̂ are in the paper's units (A²/mm², N·mm²/A²).  The
weight error then obeys k̃(k+1) ≈ (1 - η φ²) k̃(k) once F̂_St has followed (the filter's force
lag), the time the lab states for the bias to fall.

With ``jacobian`` the scheduled filters (offline, adaptive) propagate P with the Jacobian of the
force law (the tangent factors of eq. 1 at (i, x̂), with their k_Magnet) while the state still
moves with the secant factors; without it, P moves with the secant factors too.

Consistency per filter and sample (Bar-Shalom §5.4, ``estimators.filter_consistency``):
NIS = ν² / S with the a-priori innovation ν = y - x̂_M⁻ and S = P⁻_MM + R; NEES =
eᵀ (P⁺)⁻¹ e with e the a-posteriori error of the four states against the plant's truth
(x, v, the applied load F_St, the sensor's noise-free x_M).

The kernel takes named bundles: ``DriftSchedule``, ``axial_bearing_loop.AxialPID``,
``axial_bearing_loop.FilterBank``, ``axial_bearing_loop.Identification``, ``Adaptation``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from lab_modules.estimators.adaline import siso_step
from lab_modules.estimators.fuzzy_basis_network import CENTRES, evaluate
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
    predict_exact_force,
    predict_linear,
    process_noise,
    propagate_covariance,
)
from lab_modules.loops.axial_bearing_loop import (
    SAMPLE_TIME_S,
    TOUCHDOWN_M,
    AxialRig,
    FilterBank,
    Identification,
    LoopSetup,
    plant_sample,
)
from lab_modules.plants.axial_bearing import AXIAL, force_shape, magnet_force, tangent_factors

FILTERS = ("fixed", "offline", "adaptive", "exact")
N_FILTERS = len(FILTERS)
FEEDBACK = FILTERS.index("adaptive")          # the filter the PID acts on (Fig. 8), unless measured
PER_FILTER = ("force_error_n", "force_sigma_n", "x_error_m", "nees", "nis")
COLUMNS = ("x_true_m", "x_reference_m", "current_a", "disturbance_n", "magnet_force_n", "k_magnet_true",
           "k_magnet_estimate", *[f"{f}_{q}" for f in FILTERS for q in PER_FILTER])
COLUMN = {name: j + 1 for j, name in enumerate(COLUMNS)}      # row index 0 is time
FIRST_FILTER_COLUMN = COLUMN[f"{FILTERS[0]}_{PER_FILTER[0]}"]

# loop state layout
S_T, S_X, S_V, S_XM, S_INTEGRAL, S_DERIV, S_PREV_MEAS, S_REF, S_ADALINE, S_STOPPED = range(10)
N_LOOP_STATE = 10


class DriftSchedule(NamedTuple):
    """The plant's programme: operating points and loads that repeat, and the magnet's drift."""

    segments: np.ndarray      # (n, 3) per segment: start [s], position reference [m], applied load F_St [N]
    period_s: float           # the programme repeats after this time [s]
    load_ramp_s: float        # a new load ramps in linearly over this time [s]
    k_magnet: float           # nominal k_Magnet [N m²/A²]
    start_s: float            # the drift begins at this time within the period [s]
    ramp_s: float             # 0: a step; else the drift is spread linearly over this time [s]
    change: float             # relative change of k_Magnet at the drift's end [-]


class Adaptation(NamedTuple):
    """How the ADALINE learns and how the scheduled filters propagate P."""

    target: int               # 0: the adaptive filter's force balance; 1: a force sensor (true force + noise)
    jacobian: bool            # P of the scheduled filters with the tangent factors (else the secant ones)
    k_nominal_mm: float       # k_Magnet,nominal in the ADALINE's units [N mm²/A²]


@njit(cache=True, nogil=True)
def drift_factor(tau, start_s, ramp_s, change):
    """k_Magnet / k_Magnet,nominal at time ``tau`` within the period [-]."""
    if tau < start_s:
        return 1.0
    if ramp_s <= 0.0 or tau >= start_s + ramp_s:
        return 1.0 + change
    return 1.0 + change * (tau - start_s) / ramp_s


@njit(cache=True, nogil=True)
def programme(t, schedule):
    """(position reference [m], applied load [N], k_Magnet [N m²/A²]) at time ``t`` [s]."""
    segments, period, load_ramp = schedule.segments, schedule.period_s, schedule.load_ramp_s
    tau = t % period
    seg = 0
    for j in range(segments.shape[0]):
        if tau >= segments[j, 0] - 1e-12:
            seg = j
    load = segments[seg, 2]
    if seg > 0:
        previous = segments[seg - 1, 2]
    elif t >= period:
        previous = segments[segments.shape[0] - 1, 2]     # the programme wraps round
    else:
        previous = load
    if load_ramp > 0.0 and tau - segments[seg, 0] < load_ramp:
        load = previous + (load - previous) * (tau - segments[seg, 0]) / load_ramp
    factor = drift_factor(tau, schedule.start_s, schedule.ramp_s, schedule.change)
    return segments[seg, 1], load, schedule.k_magnet * factor


@njit(cache=True, nogil=True)
def predict_scheduled(z, P, k_i, k_s, tangent_k_i, tangent_k_s, jacobian, physics, current, A, B, Q):
    """Eq. 9-10 with the secant factors (k_i [N/A], k_s [N/m]); with ``jacobian`` P and Q move with the
    tangent factors instead (the linearisation of eq. 1 at the estimate)."""
    model_matrices(k_i, k_s, physics, A, B)
    if not jacobian:
        process_noise(physics, B, Q)
        predict_linear(z, P, A, B, Q, current)
        return
    z[:] = A @ z + B[:, 0] * current + B[:, 1]
    model_matrices(tangent_k_i, tangent_k_s, physics, A, B)
    process_noise(physics, B, Q)
    propagate_covariance(P, A, Q)


NEES_STATES = 3              # x, v, F_St: the sensor state x_M is left out (module docstring)


@njit(cache=True, nogil=True)
def normalised_errors(z, P, truth, M):
    """NEES eᵀ P⁻¹ e of the a-posteriori estimate ``z`` against ``truth`` over the first ``NEES_STATES``
    states (x, v, F_St) with their block of P [-]: P⁻¹ e by Gaussian elimination with partial
    pivoting (as LAPACK's solver; on a 3×3 the call itself would cost more than the sum).  ``M``
    (``NEES_STATES`` × ``NEES_STATES`` + 1) is scratch: the loop calls this four times a sample, and
    an allocation each time would cost more than the elimination."""
    n = NEES_STATES
    for r in range(n):
        for c in range(n):
            M[r, c] = P[r, c]
        M[r, n] = truth[r] - z[r]
    for k in range(n):
        pivot = k
        for r in range(k + 1, n):
            if abs(M[r, k]) > abs(M[pivot, k]):
                pivot = r
        if pivot != k:
            for c in range(n + 1):
                M[k, c], M[pivot, c] = M[pivot, c], M[k, c]
        for r in range(k + 1, n):
            factor = M[r, k] / M[k, k]
            for c in range(k, n + 1):
                M[r, c] -= factor * M[k, c]
    nees = 0.0
    for r in range(n - 1, -1, -1):                # back substitution: x_r = (P⁻¹ e)_r, in M[:, n]
        acc = M[r, n]
        for c in range(r + 1, n):
            acc -= M[r, c] * M[c, n]
        M[r, n] = acc / M[r, r]
        nees += (truth[r] - z[r]) * M[r, n]
    return nees


@njit(cache=True, nogil=True)
def run(n_steps, state, physics, schedule, pid, filters, networks, adaptation, noise, out):
    """Advance ``n_steps`` samples; writes rows (time, *COLUMNS) into ``out``; returns the rows written.

    state : (N_LOOP_STATE,) in place; physics : ``scheduled_kalman.physics_vector`` of the nominal
    model; schedule : ``DriftSchedule``; pid : ``AxialPID`` (feedback -1: measured, else ``FEEDBACK``);
    filters : ``FilterBank`` of the four ``FILTERS`` (in place); networks : ``Identification``
    (FBFNN and η); adaptation : ``Adaptation``; noise : (n_steps, 3) draws: sensor [V],
    current [A], force sensor [N]."""
    filter_z, filter_P = filters.z, filters.P
    centres, ki_w, ki_s = networks.centres, networks.ki_weights, networks.ki_widths
    ks_w, ks_s, rate = networks.ks_weights, networks.ks_widths, networks.adaline_rate
    target_mode, jacobian, k0_mm = adaptation.target, adaptation.jacobian, adaptation.k_nominal_mm
    T, sensor_gain, gap, bias, R = physics[SAMPLE], physics[SENSOR_GAIN], physics[GAP], physics[BIAS], physics[VAR_SENSOR]
    k0 = physics[K_MAGNET]
    rig = AxialRig(mass_kg=physics[MASS], gravity_m_per_s2=physics[GRAVITY], gap_m=gap, bias_current_a=bias,
                   sensor_lag_s=physics[SENSOR_LAG], sensor_gain_v_per_m=sensor_gain)
    exact_physics = physics.copy()
    A, B, Q = np.zeros((N_STATES, N_STATES)), np.zeros((N_STATES, 2)), np.zeros((N_STATES, N_STATES))
    A_fixed, B_fixed, Q_fixed = np.zeros((N_STATES, N_STATES)), np.zeros((N_STATES, 2)), np.zeros((N_STATES, N_STATES))
    model_matrices(4 * k0 * bias / gap**2, 4 * k0 * bias**2 / gap**3, physics, A_fixed, B_fixed)   # eq. 4-5
    process_noise(physics, B_fixed, Q_fixed)
    truth = np.zeros(N_STATES)
    elimination = np.empty((NEES_STATES, NEES_STATES + 1))   # [P block | e], reduced in place
    kp, ti, kd = pid.proportional_a_per_m, pid.integral_time_s, pid.derivative_a_s_per_m
    tf, tr, i_ff = pid.derivative_filter_s, pid.reference_filter_s, pid.feedforward_a
    feedback = -1 if pid.feedback < 0 else FEEDBACK
    for k in range(n_steps):
        if state[S_STOPPED] > 0:
            return k
        t = state[S_T]
        reference, load, k_magnet = programme(t, schedule)
        x, v, xm = state[S_X], state[S_V], state[S_XM]
        y = xm + noise[k, 0]
        x_meas = y / sensor_gain
        row = out[k]
        truth[0], truth[1], truth[2], truth[3] = x, v, load, xm
        for f in range(N_FILTERS):
            innovation_variance = filter_P[f, 3, 3] + R                  # S = H P⁻ Hᵀ + R
            row[FIRST_FILTER_COLUMN + 5 * f + 4] = (y - filter_z[f, 3]) ** 2 / innovation_variance   # NIS
            correct(filter_z[f], filter_P[f], y, R)
            row[FIRST_FILTER_COLUMN + 5 * f + 3] = normalised_errors(filter_z[f], filter_P[f], truth, elimination)
        # PID on the measured position or the adaptive filter's estimate (Fig. 8)
        state[S_REF] += (reference - state[S_REF]) * T / tr
        if feedback < 0:
            position = x_meas
            derivative = 0.0 if t == 0.0 else (tf * state[S_DERIV] + (x_meas - state[S_PREV_MEAS])) / (tf + T)
            state[S_DERIV], state[S_PREV_MEAS] = derivative, x_meas
        else:
            position, derivative = filter_z[feedback, 0], filter_z[feedback, 1]
        error = state[S_REF] - position
        state[S_INTEGRAL] += error * T
        command = i_ff + kp * (error + state[S_INTEGRAL] / ti) - kd * derivative
        if abs(command) > bias:
            command = bias if command > 0 else -bias
            state[S_INTEGRAL] -= error * T                               # anti-windup
        current = min(max(command + noise[k, 1], -bias), bias)
        force_true = magnet_force(current, x, k_magnet, gap, bias)
        # ADALINE on the adaptive filter's force estimate (or a force sensor), paper units
        x_adaptive = filter_z[2, 0]
        ki_fbfnn = evaluate(command, x_adaptive, centres, ki_w, ki_s)
        ks_fbfnn = evaluate(command, x_adaptive, centres, ks_w, ks_s)
        if target_mode == 0:                                             # F̂_M, the adaptive filter's
            force_target = state[S_ADALINE] / k0_mm * (ki_fbfnn * command + ks_fbfnn * x_adaptive) \
                + filter_z[2, 2] - load
        else:
            force_target = force_true + noise[k, 2]
        phi_mm = force_shape(command, x_adaptive, gap, bias) * 1e-6     # φ [A²/mm²]
        state[S_ADALINE] = siso_step(state[S_ADALINE], phi_mm, force_target, rate)
        scale = state[S_ADALINE] / k0_mm                                 # k̂ / k_0, this sample's
        row[0], row[1], row[2], row[3], row[4] = t, x, state[S_REF], current, load
        row[5], row[6], row[7] = force_true, k_magnet * 1e6, state[S_ADALINE]
        for f in range(N_FILTERS):
            base = FIRST_FILTER_COLUMN + 5 * f
            row[base] = filter_z[f, 2] - load
            row[base + 1] = np.sqrt(max(filter_P[f, 2, 2], 0.0))
            row[base + 2] = filter_z[f, 0] - x
        # predictions with the commanded current
        predict_linear(filter_z[0], filter_P[0], A_fixed, B_fixed, Q_fixed, command)
        x_offline = filter_z[1, 0]
        ki_o = evaluate(command, x_offline, centres, ki_w, ki_s)
        ks_o = evaluate(command, x_offline, centres, ks_w, ks_s)
        tki, tks = tangent_factors(command, x_offline, k0, gap, bias)
        predict_scheduled(filter_z[1], filter_P[1], ki_o, ks_o, tki, tks, jacobian, physics, command, A, B, Q)
        tki, tks = tangent_factors(command, x_adaptive, k0 * scale, gap, bias)
        predict_scheduled(filter_z[2], filter_P[2], scale * ki_fbfnn, scale * ks_fbfnn, tki, tks, jacobian, physics, command, A, B, Q)
        exact_physics[K_MAGNET] = k_magnet
        predict_exact_force(filter_z[3], filter_P[3], exact_physics, command, A, B, Q)
        x, v, xm = plant_sample(x, v, xm, current, load, k_magnet, rig, T)
        state[S_X], state[S_V], state[S_XM] = x, v, xm
        state[S_T] = t + T
        if not np.isfinite(x) or abs(x) >= TOUCHDOWN_M:
            state[S_STOPPED] = 1.0
            return k + 1
    return n_steps


@dataclass(frozen=True)
class DriftSetup:
    """The axial loop's settings (``axial_bearing_loop.LoopSetup``: programme, PID, noise, FBFNN, η,
    k̂ at the start, σ_F) and the magnet's drift."""

    loop: LoopSetup
    start_s: float = 0.2                # when k_Magnet begins to change, within the period [s]
    ramp_s: float = 0.0                 # 0: a step [s]
    change: float = -0.1                # relative change [-]
    target: str = "force balance"       # or "force sensor"
    jacobian: bool = False

    def schedule(self) -> DriftSchedule:
        segments = np.array([[s.start_s, s.reference_m, s.disturbance_n] for s in self.loop.segments])
        return DriftSchedule(segments=segments, period_s=self.loop.period_s, load_ramp_s=self.loop.load_ramp_s,
                             k_magnet=self.loop.k_magnet, start_s=self.start_s, ramp_s=self.ramp_s,
                             change=self.change)


TARGETS = ("force balance", "force sensor")


class DriftSimulation:
    """The compiled drift loop, advanced block by block (the app's ``Simulation``)."""

    sample_time_s = SAMPLE_TIME_S
    columns = COLUMNS

    def __init__(self, setup: DriftSetup, seed: int = 0):
        self.rng = np.random.default_rng(seed)
        self.state = np.zeros(N_LOOP_STATE)
        self.state[S_ADALINE] = AXIAL.k_magnet_n_m2_per_a2 * 1e6      # k̂ starts at the nominal value
        self.filter_z = np.zeros((N_FILTERS, N_STATES))
        self.filter_P = np.repeat(np.diag([20e-6, 1e-3, 1.0, 20e-3])[None] ** 2, N_FILTERS, axis=0)
        self.retuned(setup)

    def retuned(self, setup: DriftSetup) -> DriftSimulation:
        """The same running loop with new settings (state, filters, k̂ and noise stream kept)."""
        loop = setup.loop
        self.setup, self.physics, self.schedule = setup, loop.physics(), setup.schedule()
        self.pid = loop.controller()
        ki_weights, ki_widths, ks_weights, ks_widths = (np.ascontiguousarray(a, dtype=np.float64)
                                                        for a in (*loop.fbfnn_ki, *loop.fbfnn_ks))
        self.networks = Identification(centres=CENTRES, ki_weights=ki_weights, ki_widths=ki_widths,
                                       ks_weights=ks_weights, ks_widths=ks_widths, stencil_a=loop.stencil_a,
                                       stencil_m=loop.stencil_m, adaline_rate=loop.adaline_rate)
        self.adaptation = Adaptation(target=TARGETS.index(setup.target), jacobian=bool(setup.jacobian),
                                     k_nominal_mm=loop.k_magnet * 1e6)
        return self

    def advance(self, n_steps: int) -> np.ndarray:
        loop = self.setup.loop
        noise = np.column_stack([self.rng.normal(0.0, np.sqrt(loop.var_sensor_v2), n_steps),
                                 self.rng.normal(0.0, np.sqrt(loop.var_process_a2), n_steps),
                                 self.rng.normal(0.0, loop.force_noise_n, n_steps)])
        out = np.empty((n_steps, 1 + len(COLUMNS)))
        n = run(n_steps, self.state, self.physics, self.schedule, self.pid,
                FilterBank(z=self.filter_z, P=self.filter_P), self.networks, self.adaptation, noise, out)
        return out[:n]

    def status_message(self) -> str:
        if self.state[S_STOPPED] > 0:
            return f"Touchdown: the rotor reached the retainer bearing at ±{TOUCHDOWN_M * 1e3:g} mm."
        return ""
