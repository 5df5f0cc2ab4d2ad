"""The bearing axis in closed loop with an extended Kalman filter (paper 000, §III).

One call of the compiled ``run`` advances the loop by ``n_steps`` samples of
T = 50 µs.  Per sample k:

1. sensors    y = (K_mx x_d + eta_x, K_mi i + eta_i)                      (eq. 14, 16)
2. filter     correction with y                                          (eq. 6)
3. feedback   measured K_mx x_d + eta_x, or the estimate K_mx x_hat      (§III-B: the undelayed estimate)
4. control    e = K_mx r - feedback;  i_ref = PID(e) + feedforward, clipped at the amplifier limit
              feedforward (§III-B, after Fig. 4) = -f_z_hat / (k_i K_a): the estimated force
              turned into the current that cancels it, through the rated k_i
5. filter     prediction with i_ref                                      (eq. 6, 15)
6. plant      one RK4 sample of eq. 10-12 (``radial_axis_loop.rk4_step``) with the disturbance
              force f_z, plus process noise on v and i

The plant is always the nonlinear one of eq. 10-12; the filter is either
``extended_kalman.ParameterEKF``'s model (§III-A) or ``DisturbanceEKF``'s (§III-B).
The kernel takes named bundles: ``radial_axis_loop.Rotor``, ``ExtendedFilter``,
``pid.DiscreteController``, ``EKFFeedback`` and ``radial_axis_loop.Inputs``/``Noise``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import control
import numba
import numpy as np
from scipy.signal import max_len_seq

from lab_modules import analysis
from lab_modules.controllers.pid import DiscreteController, controller_step
from lab_modules.estimators import extended_kalman as ef
from lab_modules.estimators.extended_kalman import N_STATES
from lab_modules.estimators.filter_history import FilterModel, FilterTape
from lab_modules.estimators.kalman import correction
from lab_modules.loops.radial_axis_loop import Inputs, Noise, Rotor, rk4_step
from lab_modules.plants.radial_bearing import RIG, BearingAxis

OK, DIVERGED, TOUCHDOWN, FILTER_DIVERGED = 0, 1, 2, 3
MEASUREMENTS = (("position sensor", "V"), ("current sensor", "V"))

#: Columns of the trace written by ``run``.  ``*_true_*`` are the plant's:
#: k_x, k_i the analytic derivatives of eq. 10 at the true (x, i).  The
#: estimated factors are states 4-5 of ``ParameterEKF`` or, for
#: ``DisturbanceEKF``, read from Phi by eq. 18 (no sigma: NaN); the force
#: estimate exists only in ``DisturbanceEKF`` (NaN otherwise).
TRACE_COLUMNS = ("x_true_m", "x_measured_m", "x_estimated_m", "x_sigma_m", "current_a",
                 "current_reference_v", "reference_m", "force_true_n", "force_estimated_n",
                 "force_sigma_n", "kx_true_n_per_m", "kx_estimated_n_per_m", "kx_sigma_n_per_m",
                 "ki_true_n_per_a", "ki_estimated_n_per_a", "ki_sigma_n_per_a", "nis", "velocity_true_m_per_s")


class ExtendedFilter(NamedTuple):
    """The EKF's arrays as the kernel takes them (eq. 6-9 or 14-18), 5 states:
    (x [m], v [m/s], i [A], k_i [N/A], k_x [N/m]) for ``LINEARISED`` (§III-A) or
    (x [m], v [m/s], i [A], x_d [m], f_z [N]) for ``NONLINEAR`` (§III-B)."""

    model: int           # ef.LINEARISED or ef.NONLINEAR
    x_hat: np.ndarray    # (5,) estimate, corrected and predicted in place [state units]
    P: np.ndarray        # (5, 5) error covariance, in place [state unit x state unit]
    Q: np.ndarray        # (5, 5) process-noise covariance per sample [state units²]
    R_diag: np.ndarray   # (2,) sensor noise variances: position [V²], current [V²]
    C: np.ndarray        # (2, 5) measurement matrix G (eq. 9, 14) [V per state unit]
    physics: np.ndarray  # (11,) the filter's ``extended_kalman.physics_vector`` (its own sensor lag T_mx [s])


class EKFFeedback(NamedTuple):
    """What the PID acts on, the force feedforward and the amplifier's limit."""

    use_estimate: bool           # feed back K_mx x_hat[0] instead of the measured position
    feedforward_v_per_n: float   # i_ref [V] per estimated newton of f_z (0: no feedforward)
    u_limit_v: float             # amplifier input limit [V] (current limit / K_a)


@numba.njit(nogil=True, cache=True)
def run(n_steps, rotor, ekf, controller, feedback, inputs, noise, trace):
    """Advance the loop by ``n_steps`` samples (see module docstring).

    rotor : ``radial_axis_loop.Rotor``, the true (x, v, i, x_d), stepped in place, and the
        plant's ``extended_kalman.physics_vector`` (it differs from the filter's in T_mx when
        the filter's lag is wrong).
    ekf : ``ExtendedFilter``, the filter's model, estimate and covariance (in place).
    controller : ``pid.DiscreteController``, the PID (e [V] -> i_ref [V]).
    feedback : ``EKFFeedback``, measured or estimated position, feedforward, amplifier limit.
    inputs : ``radial_axis_loop.Inputs``, (n_steps,) reference position [m], force f_z [N].
    noise : ``radial_axis_loop.Noise``, (n_steps, 4) standard normal draws scaled by
        (v [m/s], i [A], sensor x [V], sensor i [V]) per sample.
    trace : (n_steps, len(TRACE_COLUMNS)) output.

    Returns (status, steps_done).
    """
    # every field read once, before the loop: an array read out of a bundle inside the loop
    # would cost a reference count per sample
    plant, plant_physics, touchdown_m = rotor.state, rotor.physics, rotor.touchdown_m
    model, x_hat, P, Q, R_diag, C, filter_physics = ekf.model, ekf.x_hat, ekf.P, ekf.Q, ekf.R_diag, ekf.C, ekf.physics
    ctrl, Ac, Bc, Cc, Dc = controller.state, controller.A, controller.B, controller.C, controller.D
    use_estimate, feedforward_v_per_n, u_limit = feedback.use_estimate, feedback.feedforward_v_per_n, feedback.u_limit_v
    reference_m, disturbance_n, draws, noise_sigma = inputs.reference_m, inputs.disturbance_n, noise.draws, noise.sigma
    T, Tmx, K_mx, K_mi = plant_physics[8], plant_physics[7], plant_physics[9], plant_physics[10]
    y, gain = np.empty(2), np.empty((2, N_STATES))
    F, Phi, work = np.empty((N_STATES, N_STATES)), np.empty((N_STATES, N_STATES)), \
        np.empty((6, N_STATES, N_STATES))
    work_ctrl = np.empty(max(ctrl.shape[0], 1))
    k1, k2, k3, k4, tmp = np.empty(4), np.empty(4), np.empty(4), np.empty(4), np.empty(4)
    nan = np.nan
    for k in range(n_steps):
        # 1.-2. sensors and filter correction
        y[0] = K_mx * plant[3] + noise_sigma[2] * draws[k, 2]
        y[1] = K_mi * plant[2] + noise_sigma[3] * draws[k, 3]
        nis = ef.update(x_hat, P, C, y, R_diag, gain, N_STATES)
        # 3.-4. feedback, PID and feedforward
        fed_back = K_mx * x_hat[0] if use_estimate else y[0]
        e = K_mx * reference_m[k] - fed_back
        feedforward = feedforward_v_per_n * x_hat[4] if model == ef.NONLINEAR else 0.0
        u = controller_step(e, feedforward, u_limit, ctrl, Ac, Bc, Cc, Dc, work_ctrl)
        row = trace[k]
        row[0], row[1], row[2] = plant[0], y[0] / K_mx, x_hat[0]
        row[3], row[4], row[5] = np.sqrt(max(P[0, 0], 0.0)), plant[2], u
        row[6], row[7] = reference_m[k], disturbance_n[k]
        row[10], row[13] = ef.local_factors(plant[0], plant[2], plant_physics)
        row[16], row[17] = nis, plant[1]
        if model == ef.NONLINEAR:
            row[8], row[9] = x_hat[4], np.sqrt(max(P[4, 4], 0.0))
        else:
            row[8], row[9] = nan, nan
            row[11], row[12] = x_hat[4], np.sqrt(max(P[4, 4], 0.0))
            row[14], row[15] = x_hat[3], np.sqrt(max(P[3, 3], 0.0))
        # 5. filter prediction (eq. 18 reads the factors from its Phi)
        ef.predict(model, x_hat, P, u, Q, filter_physics, F, Phi, work)
        if model == ef.NONLINEAR:
            row[11], row[14] = ef.factors_from_phi(Phi, filter_physics)
            row[12], row[15] = nan, nan
        # 6. plant
        rk4_step(plant, u, disturbance_n[k], plant_physics, T, k1, k2, k3, k4, tmp)
        if Tmx <= 0.0:
            plant[3] = plant[0]
        plant[1] += noise_sigma[0] * draws[k, 0]
        plant[2] += noise_sigma[1] * draws[k, 1]
        if not (np.isfinite(plant[0]) and np.isfinite(plant[1])):
            return DIVERGED, k + 1
        if not (np.isfinite(x_hat[0]) and np.isfinite(P[0, 0]) and np.isfinite(x_hat[3])
                and np.isfinite(x_hat[4])):
            return FILTER_DIVERGED, k + 1
        if abs(plant[0]) >= touchdown_m:
            return TOUCHDOWN, k + 1
    return OK, n_steps


def no_input(t: np.ndarray) -> np.ndarray:
    """Zero at every sample time."""
    return np.zeros_like(t)


_PRBS_BITS = 2.0 * max_len_seq(9)[0] - 1.0


# -- inputs: sample times [s] -> reference position [m] or force [N] ----------
@dataclass(frozen=True)
class Prbs:
    """Offset plus a pseudo-random binary sequence of ±amplitude (§III-A: the
    excitation superimposed on the reference).  A maximum-length sequence of
    9 bits (511 bits, ``scipy.signal.max_len_seq``), each held ``bit_time_s``.
    The offset ramps in over ``offset_ramp_s`` so that it does not kick the loop."""

    amplitude: float
    bit_time_s: float
    offset: float = 0.0
    offset_ramp_s: float = 0.05

    def __call__(self, t: np.ndarray) -> np.ndarray:
        bits = _PRBS_BITS[(t // self.bit_time_s).astype(int) % _PRBS_BITS.size]
        return Ramp(self.offset, self.offset_ramp_s)(t) + self.amplitude * bits


@dataclass(frozen=True)
class Step:
    """0 before ``time_s``, ``amplitude`` from then on."""

    amplitude: float
    time_s: float

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.where(t >= self.time_s, self.amplitude, 0.0)


@dataclass(frozen=True)
class SquareWave:
    """Period ``period_s``: first half 0, second half ``amplitude``."""

    amplitude: float
    period_s: float

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.where(np.mod(t, self.period_s) >= 0.5 * self.period_s, self.amplitude, 0.0)


@dataclass(frozen=True)
class Ramp:
    """From 0 linearly to ``amplitude`` over ``ramp_s``, then constant (a static load)."""

    amplitude: float
    ramp_s: float

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return self.amplitude * np.clip(t / self.ramp_s, 0.0, 1.0)


@dataclass(frozen=True)
class Sine:
    """0 until ``start_s``, then amplitude sin(2 pi (t - start_s) / period_s)."""

    amplitude: float
    period_s: float
    start_s: float = 0.0

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return self.amplitude * np.sin(2 * np.pi * np.maximum(t - self.start_s, 0.0) / self.period_s)


@dataclass(frozen=True)
class EKFLoopSetup:
    """One experiment: rig, noise, filter, PID and the inputs (SI units).

    Noise standard deviations are per sample (T = 50 µs); the plant's process
    noise enters v (as the force ``process_force_n``) and i.  ``reference`` and
    ``disturbance`` map sample times [s] to the reference position [m] and the
    disturbance force f_z [N], counted from ``input_start_s``; ``experiment``
    names that input programme (a retune to another one restarts it).
    """

    model: int                                   # ef.LINEARISED (§III-A) or ef.NONLINEAR (§III-B)
    controller: control.StateSpace
    filter_x0: np.ndarray
    filter_P0: np.ndarray
    filter_Q: np.ndarray
    filter_R_diag: np.ndarray = field(default_factory=lambda: ef.PAPER_R_DIAG.copy())
    filter_sensor_lag_s: float = 0.0
    plant_sensor_lag_s: float = 0.0
    use_estimate: bool = False
    feedforward: bool = False
    sensor_noise_m: float = 1.33e-6
    current_noise_a: float = 1.87
    process_force_n: float = 0.5
    process_current_a: float = 1e-3
    reference: Callable[[np.ndarray], np.ndarray] = no_input
    disturbance: Callable[[np.ndarray], np.ndarray] = no_input
    experiment: str = ""
    input_start_s: float = 0.0
    rig: BearingAxis = RIG

    @property
    def noise_sigma(self) -> np.ndarray:
        rig = self.rig
        return np.array([self.process_force_n * rig.sample_time_s / rig.equivalent_mass_kg,
                         self.process_current_a, rig.position_sensor_gain_v_per_m * self.sensor_noise_m,
                         rig.current_sensor_gain_v_per_a * self.current_noise_a])


class EKFLoopSimulation:
    """Time simulation of an ``EKFLoopSetup`` (the app's ``Simulation`` protocol).

    Owns its seeded noise stream; ``advance`` releases the GIL in the kernel.
    """

    columns = TRACE_COLUMNS

    def __init__(self, setup: EKFLoopSetup, seed: int = 0):
        self.setup = setup
        self.rng = np.random.default_rng(seed)
        rig = setup.rig
        self.sample_time_s = rig.sample_time_s
        self.plant = np.zeros(4)
        self.x_hat = np.array(setup.filter_x0, dtype=float)
        self.P = np.array(setup.filter_P0, dtype=float)
        self._Q = np.ascontiguousarray(setup.filter_Q, dtype=float)
        self._R_diag = np.ascontiguousarray(setup.filter_R_diag, dtype=float)
        self._C = ef.measurement_matrix(setup.model, rig)
        self._plant_physics = ef.physics_vector(rig, setup.plant_sensor_lag_s)
        self._filter_physics = ef.physics_vector(rig, setup.filter_sensor_lag_s)
        controller = setup.controller
        self._ctrl_matrices = tuple(np.ascontiguousarray(np.atleast_2d(np.asarray(M, dtype=float)))
                                    for M in (controller.A, controller.B, controller.C, controller.D))
        self.ctrl = np.zeros(self._ctrl_matrices[0].shape[0])
        self._u_limit = rig.current_limit_a / rig.amplifier_gain_a_per_v
        self._feedforward = (-1.0 / (rig.ki_n_per_a * rig.amplifier_gain_a_per_v)
                             if setup.feedforward else 0.0)
        self.step = 0
        self.status = OK
        self._last_correction = None                   # (prior x̂, prior P, y, time) of the last sample
        self.tape = FilterTape(FilterModel.propagated(
            self.title(), rig.sample_time_s, 1, self._C, self._Q, self._R_diag, self.states(), MEASUREMENTS,
            ef.propagation(setup.model, self._Q, self._filter_physics), ef.PREDICTION_LATEX))

    def retuned(self, setup: EKFLoopSetup) -> EKFLoopSimulation:
        """A simulation with new settings that carries on from this one's state
        (rotor, filter, PID, time, noise stream), so a slider move changes the
        running experiment; a new filter starting point restarts the filter only,
        a new input programme (``experiment``) starts its inputs now."""
        old = self.setup
        start = old.input_start_s if setup.experiment == old.experiment else self.time_s
        new = EKFLoopSimulation(replace(setup, input_start_s=start))
        new.rng, new.step, new.status, new.plant[:] = self.rng, self.step, self.status, self.plant
        if (np.array_equal(setup.filter_x0, old.filter_x0)
                and np.array_equal(setup.filter_P0, old.filter_P0)):
            new.x_hat[:], new.P[:] = self.x_hat, self.P
        if new.ctrl.shape == self.ctrl.shape:
            new.ctrl[:] = self.ctrl
        return new

    @property
    def time_s(self) -> float:
        return self.step * self.sample_time_s

    def advance(self, n_steps: int) -> np.ndarray:
        """Run up to ``n_steps`` samples; trace with a leading time column [s]."""
        if self.status != OK or n_steps <= 0:
            return np.empty((0, len(TRACE_COLUMNS) + 1))
        setup = self.setup
        t = (self.step + np.arange(n_steps)) * self.sample_time_s
        reference = np.ascontiguousarray(setup.reference(t - setup.input_start_s), dtype=float)
        disturbance = np.ascontiguousarray(setup.disturbance(t - setup.input_start_s), dtype=float)
        noise = self.rng.standard_normal((n_steps, 4))
        trace = np.empty((n_steps, len(TRACE_COLUMNS)))

        rotor = Rotor(state=self.plant, physics=self._plant_physics, touchdown_m=setup.rig.touchdown_m)
        ekf = ExtendedFilter(model=setup.model, x_hat=self.x_hat, P=self.P, Q=self._Q, R_diag=self._R_diag,
                             C=self._C, physics=self._filter_physics)
        Ac, Bc, Cc, Dc = self._ctrl_matrices
        controller = DiscreteController(state=self.ctrl, A=Ac, B=Bc, C=Cc, D=Dc)
        feedback = EKFFeedback(use_estimate=setup.use_estimate, feedforward_v_per_n=self._feedforward,
                               u_limit_v=self._u_limit)

        def part(first: int, last: int) -> tuple[int, int]:
            return run(last - first, rotor, ekf, controller, feedback,
                       Inputs(reference_m=reference[first:last], disturbance_n=disturbance[first:last]),
                       Noise(draws=noise[first:last], sigma=setup.noise_sigma), trace[first:last])

        prior = self.x_hat.copy(), self.P.copy()
        status, done = part(0, n_steps)
        trace = trace[:done]
        # eq. 14, 16: the measured position (as traced) and the true current plus the sensor's noise
        y = np.column_stack([trace[:, 1] * self._plant_physics[9],
                             self._plant_physics[10] * trace[:, 4] + setup.noise_sigma[3] * noise[:done, 3]])
        # a single step (the inspector's) keeps the prior
        self._last_correction = (*prior, y[0], t[0]) if n_steps == 1 else None
        self.tape.record(self.step, *prior, t[:done], trace[:, 5], y, self.true_states(trace))
        self.step += done
        self.status = status
        return np.column_stack([t[:done], trace])

    def true_states(self, trace: np.ndarray) -> np.ndarray:
        """The filter's states as the plant has them, per trace row (NaN: the lagged sensor's x_d,
        not traced): (x, v, i, k_i, k_x) of eq. 10 at the true (x, i), or (x, v, i, x_d, f_z)."""
        names = ("x_true_m", "velocity_true_m_per_s", "current_a") + (
            ("ki_true_n_per_a", "kx_true_n_per_m") if self.setup.model == ef.LINEARISED else ("", "force_true_n"))
        return np.column_stack([trace[:, TRACE_COLUMNS.index(name)] if name else np.full(len(trace), np.nan)
                                for name in names])

    def filter_tape(self) -> FilterTape:
        """The record of the filter's inputs since the last launch or retune (``estimators.filter_history``)."""
        return self.tape

    def title(self) -> str:
        return ("Extended Kalman filter, disturbance model (paper 000 §III-B)" if self.setup.model == ef.NONLINEAR
                else "Extended Kalman filter, parameter model (paper 000 §III-A)")

    def states(self) -> tuple[tuple[str, str], ...]:
        """(label, SI unit) of the filter's five states (eq. 8 or eq. 13)."""
        return (("position x", "m"), ("velocity v", "m/s"), ("coil current i", "A")) + (
            (("sensed position x_d (lag)", "m"), ("disturbance force f_z", "N")) if self.setup.model == ef.NONLINEAR
            else (("current factor k_i", "N/A"), ("force-displacement factor k_x", "N/m")))

    def filter_state(self) -> dict | None:
        """The EKF at the sample of the last advance(1): corrected x̂ and P, gain K, innovation and √S
        (eq. 6; the measurement is linear, G = Gamma of eq. 9/14)."""
        if self._last_correction is None:
            return None
        x_prior, P_prior, y, time_s = self._last_correction
        step = correction(x_prior, P_prior, self._C, self._R_diag, y)
        return {"title": self.title(), "time_s": float(time_s), "states": self.states(), "x": step["x"],
                "P": step["P"], "measurements": MEASUREMENTS, "K": step["K"], "innovation": step["innovation"], "innovation_sigma": np.sqrt(np.diag(step["S"]))}

    def status_message(self) -> str:
        """'' while running; what stopped the simulation otherwise."""
        t_ms = self.time_s * 1e3
        if self.status == TOUCHDOWN:
            return (f"Touchdown at t = {t_ms:.1f} ms: the rotor left the air gap "
                    f"(|x| >= {self.setup.rig.touchdown_m * 1e6:.0f} µm). The loop is unstable, "
                    "saturated or cannot hold the load at these settings; reset.")
        if self.status == DIVERGED:
            return f"Diverged at t = {t_ms:.1f} ms: the plant produced non-finite values; reset."
        if self.status == FILTER_DIVERGED:
            return (f"Filter diverged at t = {t_ms:.1f} ms: its estimate became non-finite "
                    "(Q or R far from the plant's noise, or a wrong sensor lag); reset.")
        return ""


def column(trace: np.ndarray, name: str) -> np.ndarray:
    """One named column of a trace returned by ``advance`` (column 0 is time)."""
    return trace[:, 1 + TRACE_COLUMNS.index(name)]


# -- the loop linearised at rest, broken at the plant input (margins, |S|max) ---------------------
def rest_current_a(rig: BearingAxis, position_m: float) -> float:
    """Control current [A] that holds the rotor at rest at ``position_m`` without load:
    f_m(x, i) = 0 of eq. 10, by Newton's method."""
    physics = ef.physics_vector(rig)
    current = 0.0
    for _ in range(20):
        _kx, ki = ef.local_factors(position_m, current, physics)
        current -= rig.magnetic_force(position_m, current) / ki
    return current


def loop_at_plant_input(setup: EKFLoopSetup, position_m: float = 0.0) -> control.StateSpace:
    """Open loop L (broken at i_ref, S = 1 / (1 + L)) of ``setup`` linearised at rest at
    ``position_m``: the plant is eq. 10-12 with the local k_x, k_i of eq. 10 there; the
    EKF is replaced by its steady state on the model it linearises (eq. 7), at the same point:

    * ``LINEARISED`` (§III-A): once the parameter estimates have converged to the local
      k_i, k_x they stay put (their random walk is slow), so the filter acts as the linear
      Kalman filter of eq. 2 on (x, v, i) with those factors;
    * ``NONLINEAR`` (§III-B): the 5-state model (x, v, i, x_d, f_z) with F of eq. 14 at rest,
      Phi and Gamma by a zero-order hold; the force feedforward -f_z_hat / (k_i K_a), when on,
      is a state feedback on f_z_hat.

    The PID, the feedback source (measured or estimated) and the filter's Q, R are the set-up's;
    the amplifier limit is left out (a linear analysis)."""
    rig = setup.rig
    kx, ki = rig.local_factors(position_m, rest_current_a(rig, position_m))
    local = replace(rig, kx_n_per_m=float(kx), ki_n_per_a=float(ki))   # the linear model reads only these
    plant = local.discrete_model(setup.plant_sensor_lag_s)
    R = np.diag(setup.filter_R_diag)
    state_gain = None
    if setup.model == ef.LINEARISED:
        filter_model = local.discrete_model(0.0)
        Q = np.asarray(setup.filter_Q)[:3, :3]
    else:
        physics = ef.physics_vector(rig, setup.filter_sensor_lag_s)
        F = np.zeros((N_STATES, N_STATES))
        ef.jacobian(ef.NONLINEAR, np.array([position_m, 0.0, rest_current_a(rig, position_m), position_m, 0.0]),
                    physics, F)
        B = np.zeros((N_STATES, 1))
        B[2, 0] = rig.amplifier_gain_a_per_v / rig.amplifier_lag_s
        filter_model = control.c2d(control.ss(F, B, ef.measurement_matrix(ef.NONLINEAR, rig),
                                              np.zeros((2, 1))), rig.sample_time_s, "zoh")
        Q = np.asarray(setup.filter_Q)
        if setup.feedforward:
            state_gain = np.zeros(N_STATES)
            state_gain[4] = 1.0 / (rig.ki_n_per_a * rig.amplifier_gain_a_per_v)   # u = ... - K_s x_hat
    K, _ = analysis.steady_state_kalman(filter_model, Q, R)
    compensator = analysis.compensator(filter_model, setup.controller, K, setup.use_estimate, state_gain)
    return analysis.loop_at_plant_input(plant, compensator)
