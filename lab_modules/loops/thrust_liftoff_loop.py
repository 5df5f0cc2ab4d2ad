"""The compiled lift-off loop of the 281 kg thrust bearing (paper 003, Fig. 4, 6, 7).

One call of ``run`` advances the loop by ``n_steps`` samples of T = 0.1 ms.
Per sample k:

1. sensor    z_k = x_k + V_k                                     (eq. 12)
2. filter    correction with z_k (standard form of eq. 16-18; eq. 17's misprint
             is explained in ``estimators.thrust_kalman``)
3. feedback  the measured z_k or the estimate x̂_k; error e = r − feedback [m]
4. PID       i_c = Kp e + I + D, D = Kd (e_k − e_{k−1}) / T (unfiltered backward
             difference, or through a first-order filter τ_d), or D = −Kd v̂ on
             the filter's velocity; clipped at the current limit; the
             integral stops while the output is clipped and growing (anti-windup)
5. current   coil current i from the command through G(s) (§3.1, ZOH), or i = i_c
6. filter    prediction with the *measured* coil current i (eq. 14-15): G(s)
             is outside the filter's model; the fixed Taylor or exact matrices, or
             re-linearised at the estimate (``estimators.thrust_ekf``), then the
             touchdown stop if the filter knows it
7. plant     one sample of eq. 5 (linear, exact ZOH) or of eq. 2-3 (nonlinear,
             RK4), force disturbance f_dis held over the sample, gravity in the
             vertical variant; the touchdown bearing stops the collar at
             ±clearance (inelastic)

The gains are in SI units here (Kp [A/m] ...); the exercise converts the
paper's A/mm.  The kernel releases the GIL, so browser tabs run in parallel.
It takes named bundles: ``Collar``, ``CurrentLoop``, the filter's
``kalman.LinearFilter`` and ``thrust_ekf.ThrustPrediction``, ``LiftoffPID`` and ``LiftoffNoise``.
The loop as a linear system (poles, noise, margins) is ``loops.thrust_liftoff_linear``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numba
import numpy as np
import scipy.signal

from lab_modules.estimators.filter_history import FilterTape
from lab_modules.estimators.kalman import STATE_SIZE, correction, update
from lab_modules.estimators.thrust_ekf import history_model, predict_thrust, thrust_prediction
from lab_modules.estimators.thrust_kalman import H, ThrustFilterDesign
from lab_modules.plants.thrust_bearing import (
    GRAVITY_M_PER_S2,
    TABLE_1,
    ThrustBearing,
    discrete_current_loop,
    force_and_stiffness,
)

OK, DIVERGED, TOUCHDOWN, NO_LIFTOFF = 0, 1, 2, 3
JIT = {"nogil": True, "cache": True, "error_model": "numpy"}

#: Columns written by ``run`` after its time column [s].
KERNEL_COLUMNS = ("x_true_m", "x_measured_m", "x_estimated_m", "x_sigma_m", "velocity_true_m_per_s",
                  "velocity_estimated_m_per_s", "current_command_a", "current_a", "kalman_gain_x",
                  "estimation_error_m")
FILTER_TITLE = "Kalman filter of the thrust bearing (paper 003 §3)"
EXTENDED_FILTER_TITLE = "Extended Kalman filter of the thrust bearing (paper 003 §1.2, eq. 2 re-linearised)"
STATES = (("collar position x", "m"), ("collar velocity v", "m/s"))
MEASUREMENTS = (("position sensor Z", "m"),)
#: Constant columns the simulation adds (lines on the scope).
LINE_COLUMNS = ("touchdown_upper_m", "touchdown_lower_m", "current_limit_a", "current_limit_negative_a", "zero")
TRACE_COLUMNS = KERNEL_COLUMNS + LINE_COLUMNS
COLUMN = {name: i for i, name in enumerate(TRACE_COLUMNS)}

#: The collar has lifted once it is this far from the stop it started on (not in the paper).
LIFT_MARGIN_M = 0.05e-3
#: Lift-off must happen within this time, or the run stops (not in the paper).
MAX_REST_S = 0.5


@numba.njit(**JIT)
def _acceleration(x, i, f_ext, nonlinear, c):
    """d²x/dt² [m/s²]: eq. 5 (linear) or eq. 2-3 (nonlinear); c = force constants
    (m, k_i, |k_x|, i0, k_f, x0, smallest gap), f_ext = disturbance + gravity force [N]."""
    m = c[0]
    if not nonlinear:
        return (c[1] * i + c[2] * x + f_ext) / m
    force, _ = force_and_stiffness(x, i, c)
    return (force + f_ext) / m


@numba.njit(**JIT)
def _rk4(s, i, f_ext, c, T):
    """RK4 over one sample of (x, v) with the current and external force held."""
    x, v = s[0], s[1]
    a1 = _acceleration(x, i, f_ext, True, c)
    x2, v2 = x + 0.5 * T * v, v + 0.5 * T * a1
    a2 = _acceleration(x2, i, f_ext, True, c)
    x3, v3 = x + 0.5 * T * v2, v + 0.5 * T * a2
    a3 = _acceleration(x3, i, f_ext, True, c)
    x4, v4 = x + T * v3, v + T * a3
    a4 = _acceleration(x4, i, f_ext, True, c)
    s[0] = x + T / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
    s[1] = v + T / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)


class Collar(NamedTuple):
    """The thrust collar on its axis (eq. 2-3 or eq. 5) between the touchdown bearing's stops."""

    state: np.ndarray       # (2,) true x [m], v [m/s], in place
    constants: np.ndarray   # (7,) m [kg], k_i [N/A], |k_x| [N/m], i0 [A], k_f [N m²/A²], x0 [m],
    #                         smallest gap [m] (``ThrustBearing.force_constants``, see ``_acceleration``)
    nonlinear: bool         # eq. 2-3 by RK4; False: the exact ZOH matrices of eq. 5 below
    A: np.ndarray           # (2, 2) exact discrete eq. 5 on (x, v) [-, s; 1/s, -]
    B_force: np.ndarray     # (2,) column of a force held over the sample [m/N, m/(s N)]
    gravity_n: float        # force of gravity on the axis [N]: 0 horizontal, −m g vertical
    clearance_m: float      # the touchdown bearing stops the collar at ±clearance [m]
    liftoff: np.ndarray     # (2,) lifted (0/1), samples spent resting on the start stop, in place


class CurrentLoop(NamedTuple):
    """The coil's current loop G(s) of §3.1 (ZOH), command i_c [A] -> coil current i [A]."""

    active: bool        # False: i = i_c
    state: np.ndarray   # (2,) state of G, in place [the realisation's own units]
    A: np.ndarray       # (2, 2) state matrix [-]
    B: np.ndarray       # (2,) input column [A per A]
    C: np.ndarray       # (2,) output row [A per A]
    D: float            # feedthrough [A/A]


class LiftoffPID(NamedTuple):
    """The PID of paper 003 (module docstring, step 4), SI gains."""

    state: np.ndarray               # (3,) integral [A], previous error [m], derivative term [A], in place
    proportional_a_per_m: float     # Kp [A/m]
    integral_a_per_m_s: float       # Ki [A/(m s)]
    derivative_a_s_per_m: float     # Kd [A s/m]
    derivative_filter: float        # τ_d / (τ_d + T) [-] (0: unfiltered backward difference)
    current_limit_a: float          # the command is clipped at ±limit [A]
    use_estimate: bool              # feed back the estimate x̂ instead of the measured z
    derivative_from_velocity: bool  # with the estimate: D = −Kd v̂ on the filter's velocity


class LiftoffNoise(NamedTuple):
    """The noise of one call: standard normal draws and their scales."""

    draws: np.ndarray   # (n_steps, 2) standard normal draws for the sensor and the force [-]
    sigma: np.ndarray   # (2,) σ_v of the sensor [m], σ_f of the force disturbance [N]


@numba.njit(**JIT)
def run(n_steps, first_step, T, collar, current_loop, kalman, prediction, pid, noise, trace):
    """Advance the loop by ``n_steps`` samples of T [s] (module docstring).

    collar : ``Collar``, the true state, plant and touchdown bearing (state and lift-off in place);
    current_loop : ``CurrentLoop``, G(s) (state in place);
    kalman : ``kalman.LinearFilter``, the filter, padded to ``STATE_SIZE`` (in place);
    prediction : ``thrust_ekf.ThrustPrediction``, fixed or re-linearised model, stop known or not;
    pid : ``LiftoffPID``, gains and state (in place);
    noise : ``LiftoffNoise`` for the sensor and the force;
    trace (n_steps, 1 + len(KERNEL_COLUMNS)) output.

    Returns (status, steps_done)."""
    # every field read once, before the loop: reading an array out of a bundle in the loop
    # would count a reference per sample
    plant, constants, memory, clearance_m = collar.state, collar.constants, collar.liftoff, collar.clearance_m
    nonlinear, plant_A, plant_B_force, gravity_n = collar.nonlinear, collar.A, collar.B_force, collar.gravity_n
    coil, G_A, G_B, G_C, G_D = current_loop.state, current_loop.A, current_loop.B, current_loop.C, current_loop.D
    use_current_loop = current_loop.active
    x_hat, P, A_f, B_f, C_f, Q_f, R_diag = kalman.x_hat, kalman.P, kalman.A, kalman.B, kalman.C, kalman.Q, kalman.R_diag
    pid_state, use_estimate, derivative_from_velocity = pid.state, pid.use_estimate, pid.derivative_from_velocity
    draws, noise_sigma = noise.draws, noise.sigma
    y = np.empty(1)
    gain = np.empty((1, STATE_SIZE))
    work_x, work_P = np.empty(STATE_SIZE), np.empty((STATE_SIZE, STATE_SIZE))
    Kp, Ki, Kd = pid.proportional_a_per_m, pid.integral_a_per_m_s, pid.derivative_a_s_per_m
    alpha, limit = pid.derivative_filter, pid.current_limit_a
    max_rest = MAX_REST_S / T
    for k in range(n_steps):
        # 1. sensor, 2. filter correction
        z = plant[0] + noise_sigma[0] * draws[k, 0]
        y[0] = z
        update(x_hat, P, C_f, y, R_diag, gain, STATE_SIZE)
        # 3. feedback, 4. PID
        e = -(x_hat[0] if use_estimate else z)
        if use_estimate and derivative_from_velocity:
            raw_d = -Kd * x_hat[1]
        else:
            raw_d = Kd * (e - pid_state[1]) / T
        pid_state[1] = e
        pid_state[2] = alpha * pid_state[2] + (1.0 - alpha) * raw_d
        wanted = Kp * e + pid_state[0] + pid_state[2]
        command = min(max(wanted, -limit), limit)
        if command == wanted or wanted * e < 0.0:
            pid_state[0] += Ki * T * e
        # 5. current loop
        if use_current_loop:
            i = G_C[0] * coil[0] + G_C[1] * coil[1] + G_D * command
            c0 = G_A[0, 0] * coil[0] + G_A[0, 1] * coil[1] + G_B[0] * command
            c1 = G_A[1, 0] * coil[0] + G_A[1, 1] * coil[1] + G_B[1] * command
            coil[0], coil[1] = c0, c1
        else:
            i = command
        trace[k, 0] = (first_step + k) * T
        trace[k, 1] = plant[0]
        trace[k, 2] = z
        trace[k, 3] = x_hat[0]
        trace[k, 4] = np.sqrt(max(P[0, 0], 0.0))
        trace[k, 5] = plant[1]
        trace[k, 6] = x_hat[1]
        trace[k, 7] = command
        trace[k, 8] = i
        trace[k, 9] = gain[0, 0]
        trace[k, 10] = x_hat[0] - plant[0]
        # 6. filter prediction with the measured coil current
        predict_thrust(x_hat, P, A_f, B_f, i, Q_f, prediction, work_x, work_P)
        # 7. plant and touchdown bearing
        f_ext = noise_sigma[1] * draws[k, 1] + gravity_n
        if nonlinear:
            _rk4(plant, i, f_ext, constants, T)
        else:
            force = constants[1] * i + f_ext
            x_new = plant_A[0, 0] * plant[0] + plant_A[0, 1] * plant[1] + plant_B_force[0] * force
            v_new = plant_A[1, 0] * plant[0] + plant_A[1, 1] * plant[1] + plant_B_force[1] * force
            plant[0], plant[1] = x_new, v_new
        contact = False
        if plant[0] <= -clearance_m:
            plant[0], plant[1], contact = -clearance_m, max(plant[1], 0.0), True
        elif plant[0] >= clearance_m:
            plant[0], plant[1], contact = clearance_m, min(plant[1], 0.0), True
        if not (np.isfinite(plant[0]) and np.isfinite(plant[1]) and np.isfinite(x_hat[0])
                and np.isfinite(P[0, 0])):
            return DIVERGED, k + 1
        if memory[0] == 0.0:
            if clearance_m - abs(plant[0]) > LIFT_MARGIN_M:
                memory[0] = 1.0
            else:
                memory[1] += 1.0
                if memory[1] > max_rest:
                    return NO_LIFTOFF, k + 1
        elif contact:
            return TOUCHDOWN, k + 1
    return OK, n_steps


@dataclass(frozen=True)
class ThrustSetup:
    """One lift-off experiment, SI units throughout (the exercise converts its sliders)."""

    bearing: ThrustBearing = TABLE_1
    proportional_a_per_m: float = 3e3             # Table 1: 3 A/mm
    integral_a_per_m_s: float = 10e3              # 10 A/(mm s)
    derivative_a_s_per_m: float = 22.0            # 0.022 A s/mm
    derivative_filter_s: float = 0.0
    current_limit_a: float = 10.0
    use_estimate: bool = False
    derivative_from_velocity: bool = False
    current_loop: bool = True
    nonlinear: bool = False
    vertical: bool = False
    sensor_noise_m: float = 5e-6
    force_noise_n: float = 0.0
    filter_q_n2: float = ThrustFilterDesign().process_noise_n2
    filter_r_factor: float = 1.0
    start_position_m: float = -0.75e-3
    sensor_noise_correlation_s: float = 0.0        # > 0: first-order coloured sensor noise (std stays σ_v)
    noise_on: bool = True                          # False: the same run without any noise draws
    filter_exact_model: bool = False               # True: the filter on the exact ZOH matrices, not eq. 9-11
    filter_extended: bool = False                  # True: eq. 2 re-linearised at the estimate every sample
    filter_knows_stop: bool = False                # True: the filter clamps its prediction at the stop

    @property
    def design(self) -> ThrustFilterDesign:
        """The linear filter; the extended one starts from its Taylor matrices and shares its steady
        state at the centre (``estimators.thrust_ekf``)."""
        return ThrustFilterDesign(self.filter_q_n2, self.filter_r_factor * self.sensor_noise_m**2, self.bearing,
                                  self.filter_exact_model and not self.filter_extended)

    @property
    def gravity_n(self) -> float:
        """Gravity's force on the axis: the collar rests on the lower stop (x < 0) when vertical."""
        return -self.bearing.mass_kg * GRAVITY_M_PER_S2 if self.vertical else 0.0

    def with_changes(self, **changes) -> ThrustSetup:
        return replace(self, **changes)


@dataclass
class ThrustSimulation:
    """A running lift-off: ``advance`` returns rows (time, *TRACE_COLUMNS); ``status_message`` says why it stopped."""

    setup: ThrustSetup
    seed: int = 0
    columns: tuple[str, ...] = TRACE_COLUMNS
    step: int = 0
    status: int = OK
    explanation: str = ""                          # appended to the stop message (e.g. the linear verdict)
    relaunch_s: float = 0.0                        # > 0: lift off again every relaunch_s (browser view)

    def __post_init__(self):
        self.sample_time_s = self.setup.bearing.sample_time_s
        self.rng = np.random.default_rng(self.seed)
        self._configure()
        self.relaunch()

    def relaunch(self) -> None:
        """Back to the start: collar at rest at the start position, filter at X0 and P0
        (§3), PID and current loop at rest."""
        s, b = self.setup, self.setup.bearing
        self.plant = np.array([s.start_position_m, 0.0])
        self.coil = np.zeros(2)
        self.filter = s.design.filter(x0=(s.start_position_m, 0.0))
        self.pid = np.array([0.0, -s.start_position_m, 0.0])
        resting = b.touchdown_clearance_m - abs(s.start_position_m) <= LIFT_MARGIN_M
        self.memory = np.array([0.0 if resting else 1.0, 0.0])
        self.launched_at = self.step
        self._bundle()

    def _bundle(self) -> None:
        """The kernel's bundles over the simulation's arrays, made when those arrays or the
        settings change (a call of the kernel may cover a fraction of a millisecond)."""
        s, b, kf = self.setup, self.setup.bearing, self.filter
        Phi, Gamma = self._plant
        self._collar = Collar(state=self.plant, constants=self._constants, nonlinear=s.nonlinear, A=Phi,
                              B_force=Gamma, gravity_n=s.gravity_n, clearance_m=b.touchdown_clearance_m,
                              liftoff=self.memory)
        G_A, G_B, G_C, G_D = self._current
        self._current_loop = CurrentLoop(active=s.current_loop, state=self.coil, A=G_A, B=G_B, C=G_C, D=G_D)
        self._kalman = kf.arrays()
        self._prediction = thrust_prediction(b, s.filter_extended, s.filter_knows_stop)
        self.tape = FilterTape(history_model(kf, self._prediction, self.filter_title, STATES, MEASUREMENTS))
        self._pid = LiftoffPID(state=self.pid, proportional_a_per_m=s.proportional_a_per_m,
                               integral_a_per_m_s=s.integral_a_per_m_s, derivative_a_s_per_m=s.derivative_a_s_per_m,
                               derivative_filter=self._derivative_filter, current_limit_a=s.current_limit_a,
                               use_estimate=s.use_estimate, derivative_from_velocity=s.derivative_from_velocity)

    def _configure(self):
        s, b = self.setup, self.setup.bearing
        T = b.sample_time_s
        Phi, _, Gamma = b.exact_discretisation()
        self._plant = (Phi, Gamma)
        self._current = discrete_current_loop(T)
        self._derivative_filter = s.derivative_filter_s / (s.derivative_filter_s + T)
        self._sigma = np.array([s.sensor_noise_m, s.force_noise_n]) if s.noise_on else np.zeros(2)
        self._constants = b.force_constants()
        self._lines = np.array([b.touchdown_clearance_m, -b.touchdown_clearance_m,
                                s.current_limit_a, -s.current_limit_a, 0.0])

    def retuned(self, setup: ThrustSetup) -> ThrustSimulation:
        """The running experiment with new settings: plant, filter estimate and PID state carry on."""
        kf = self.filter
        self.setup = setup
        design = setup.design
        Phi, B_d, Q_d = design.matrices
        kf.__init__(Phi, B_d, H, Q_d, [design.measurement_variance_m2], kf.x.copy(), kf.covariance.copy())
        self._configure()
        if not setup.noise_on:
            self._sigma[:] = 0.0
        self._bundle()
        return self

    def advance(self, n_steps: int) -> np.ndarray:
        if self.status != OK or n_steps <= 0:
            return np.empty((0, 1 + len(self.columns)))
        if self.relaunch_s <= 0.0:
            return self._advance(n_steps)
        period = max(round(self.relaunch_s / self.sample_time_s), 1)
        parts, left = [], n_steps
        while left > 0 and self.status == OK:
            if self.step - self.launched_at >= period:
                self.relaunch()
            chunk = min(left, period - (self.step - self.launched_at))
            parts.append(self._advance(chunk))
            left -= chunk
        return np.concatenate(parts)

    def _advance(self, n_steps: int) -> np.ndarray:
        s, b, kf = self.setup, self.setup.bearing, self.filter
        noise = self.rng.standard_normal((n_steps, 2))
        if s.sensor_noise_correlation_s > 0.0:
            noise[:, 0] = self._colour(noise[:, 0], np.exp(-b.sample_time_s / s.sensor_noise_correlation_s))
        trace = np.empty((n_steps, 1 + len(self.columns)))

        def part(first: int, last: int) -> tuple[int, int]:
            return run(last - first, self.step + first, b.sample_time_s, self._collar, self._current_loop,
                       self._kalman, self._prediction, self._pid, LiftoffNoise(draws=noise[first:last], sigma=self._sigma),
                       trace[first:last])

        prior = kf.state.copy(), kf.P.copy()
        status, done = part(0, n_steps)
        z = trace[:done, 1 + KERNEL_COLUMNS.index("x_measured_m")]            # eq. 13: Z = x + V
        # a single step (the inspector's) keeps the prior
        self._last_correction = (*prior, z[:1], trace[0, 0]) if n_steps == 1 else None
        truth = trace[:done, [1 + KERNEL_COLUMNS.index(c) for c in ("x_true_m", "velocity_true_m_per_s")]]
        self.tape.record(self.step, *prior, trace[:done, 0], trace[:done, 1 + KERNEL_COLUMNS.index("current_a")],
                         z, truth)
        trace[:done, 1 + len(KERNEL_COLUMNS):] = self._lines
        self.step += done
        self.status = status
        return trace[:done]

    def _colour(self, white: np.ndarray, a: float) -> np.ndarray:
        """First-order (AR(1)) noise n_k = a n_{k-1} + sqrt(1 − a²) w_k, unit variance, continuing
        from the previous chunk: sensor noise that is not white (paper §3.2's explanation of the
        remaining error)."""
        out, _ = scipy.signal.lfilter([np.sqrt(1.0 - a * a)], [1.0, -a], white,
                                          zi=[a * getattr(self, "_coloured_last", self.rng.standard_normal())])
        self._coloured_last = out[-1]
        return out

    def filter_state(self) -> dict | None:
        """The Kalman filter (§3, eq. 13) at the sample of the last advance(1): corrected x̂ and P, gain K,
        innovation and √S (see ``Simulation.filter_state``)."""
        correction_in = getattr(self, "_last_correction", None)
        if correction_in is None:
            return None
        x_prior, P_prior, y, time_s = correction_in
        kf = self.filter
        n = kf.dim_x
        step = correction(x_prior[:n], P_prior[:n, :n], kf.C[:, :n], kf.R_diag, y)
        return {"title": self.filter_title, "time_s": float(time_s), "states": STATES, "x": step["x"],
                "P": step["P"], "measurements": MEASUREMENTS, "K": step["K"],
                "innovation": step["innovation"], "innovation_sigma": np.sqrt(np.diag(step["S"]))}

    @property
    def filter_title(self) -> str:
        s = self.setup
        title = EXTENDED_FILTER_TITLE if s.filter_extended else FILTER_TITLE
        return title + (", touchdown stop in the model" if s.filter_knows_stop else "")

    def filter_tape(self) -> FilterTape:
        """The record of the filter's inputs since the last launch or retune (``estimators.filter_history``)."""
        return self.tape

    def run(self, duration_s: float) -> dict[str, np.ndarray]:
        """``duration_s`` of simulation as columns (and ``time_s``)."""
        trace = self.advance(round(duration_s / self.sample_time_s))
        out = {name: trace[:, 1 + j] for j, name in enumerate(self.columns)}
        out["time_s"] = trace[:, 0]
        return out

    def status_message(self) -> str:
        if self.status == OK:
            return ""
        t_ms = self.step * self.sample_time_s * 1e3
        clearance_mm = self.setup.bearing.touchdown_clearance_m * 1e3
        text = {DIVERGED: f"the simulation diverged at t = {t_ms:.1f} ms (a number is no longer finite).",
                TOUCHDOWN: f"the collar touched down on the ±{clearance_mm:.2f} mm touchdown bearing "
                           f"after lift-off, at t = {t_ms:.1f} ms.",
                NO_LIFTOFF: f"no lift-off: the collar still rests on the touchdown bearing after "
                            f"{MAX_REST_S * 1e3:.0f} ms."}[self.status]
        return text + (" " + self.explanation if self.explanation else "")


def liftoff_figures(trace: dict[str, np.ndarray], start_m: float, column: str = "x_true_m") -> dict:
    """Overshoot [%] of the reference 0 relative to the start distance, peak time [s] and
    2 % settling time [s] (last time outside ±2 % of the start distance)."""
    t, x = trace["time_s"], trace[column]
    if not t.size:
        return {"overshoot_percent": float("nan"), "peak_time_s": float("nan"), "settling_time_s": float("nan")}
    distance = abs(start_m) if start_m else 1.0
    sign = 1.0 if start_m <= 0 else -1.0
    peak = int(np.argmax(sign * x))
    outside = np.nonzero(np.abs(x) > 0.02 * distance)[0]
    settled = float(t[outside[-1] + 1]) if outside.size and outside[-1] + 1 < t.size else (
        float("nan") if outside.size else float(t[0]))
    return {"overshoot_percent": float(max(sign * x[peak], 0.0) / distance * 100.0),
            "peak_time_s": float(t[peak]), "settling_time_s": settled}
