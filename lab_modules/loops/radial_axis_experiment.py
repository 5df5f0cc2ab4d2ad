"""One experiment on the bearing axis: its physical set-up, its linear
analysis and its time simulation, all from the same numbers.

``AxisSetup`` says what the rig, the noise, the filter and the controller are;
``AxisSimulation`` runs it sample by sample through the compiled kernel of
``closed_loop``.  Exercises build an ``AxisSetup`` from their parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import control
import numpy as np
import scipy.signal

from lab_modules import analysis
from lab_modules.controllers.pid import DiscreteController
from lab_modules.estimators.filter_history import FilterModel, FilterTape
from lab_modules.estimators.kalman import KalmanFilter, correction, pad_vector
from lab_modules.loops import radial_axis_loop
from lab_modules.plants.radial_bearing import RIG, BearingAxis

#: The ``AxisSetup`` fields that the model and the filter depend on.
FILTER_FIELDS = {"rig", "sensor_lag_s", "sensor_noise_m", "current_noise_a", "process_force_n",
                 "process_current_a", "filter_q_velocity", "filter_q_current", "filter_r_position",
                 "filter_r_current"}

FILTER_TITLE = "Linear Kalman filter (paper 000, eq. 2)"
MEASUREMENTS = (("position sensor", "V"), ("current sensor", "V"))


@dataclass(frozen=True)
class AxisSetup:
    """Physical set-up of one bearing-axis experiment (SI units throughout).

    Noise standard deviations are per sample (T = 50 µs).  The process noise
    enters v and i as in eq. 17's diagonal Q; ``process_force_n`` is the
    equivalent force, so q_vv = (process_force_n T / m)**2.
    """

    controller: control.StateSpace
    use_estimate: bool = False
    state_gain: tuple[float, float, float] | None = None   # K on the estimate (x, v, i), LQG (eq. 22)
    nonlinear: bool = True
    sensor_lag_s: float = 0.0
    sensor_noise_m: float = 1.33e-6
    current_noise_a: float = 1.87
    process_force_n: float = 0.5
    process_current_a: float = 1e-3
    filter_q_velocity: float | None = None   # m^2/s^2; None: matched to the plant
    filter_q_current: float | None = None    # A^2; None: matched to the plant
    filter_r_position: float | None = None   # V^2; None: matched to the sensor
    filter_r_current: float | None = None    # V^2; None: matched to the sensor
    reference_step_m: float = 0.0
    disturbance_step_n: float = 0.0
    step_period_s: float = 0.1
    reference_filter: control.StateSpace | None = None   # discrete SISO filter on the reference (I-PD)
    rig: BearingAxis = RIG

    # -- the plant's true noise ------------------------------------------------
    @property
    def process_velocity_sigma(self) -> float:
        """Per-sample velocity noise [m/s] equivalent to ``process_force_n``."""
        return self.process_force_n * self.rig.sample_time_s / self.rig.equivalent_mass_kg

    @property
    def noise_sigma(self) -> np.ndarray:
        """Scales of the four noise draws per sample: v [m/s], i [A], sensor x [V], sensor i [V]."""
        rig = self.rig
        return np.array([self.process_velocity_sigma, self.process_current_a,
                         rig.position_sensor_gain_v_per_m * self.sensor_noise_m,
                         rig.current_sensor_gain_v_per_a * self.current_noise_a])

    # -- the filter (eq. 2) ----------------------------------------------------
    @cached_property
    def model(self) -> control.StateSpace:
        """Discrete linear model used by the filter and the analysis."""
        return self.rig.discrete_model(self.sensor_lag_s)

    @property
    def filter_Q(self) -> np.ndarray:
        q_v = self.process_velocity_sigma**2 if self.filter_q_velocity is None else self.filter_q_velocity
        q_i = self.process_current_a**2 if self.filter_q_current is None else self.filter_q_current
        Q = np.zeros((self.model.nstates, self.model.nstates))
        Q[1, 1], Q[2, 2] = q_v, q_i
        return Q

    @property
    def filter_R(self) -> np.ndarray:
        matched = self.noise_sigma[2:] ** 2
        r_x = matched[0] if self.filter_r_position is None else self.filter_r_position
        r_i = matched[1] if self.filter_r_current is None else self.filter_r_current
        return np.diag([r_x, r_i])

    @cached_property
    def steady_state_filter(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, P) of eq. 2 in steady state."""
        return analysis.steady_state_kalman(self.model, self.filter_Q, self.filter_R)

    @property
    def state_feedback_gain(self) -> np.ndarray | None:
        """``state_gain`` on the filter's whole state; zero on x_d, whose place
        the undelayed estimate of x takes for control (paper §III-B)."""
        if self.state_gain is None:
            return None
        gain = np.zeros(self.model.nstates)
        gain[:3] = self.state_gain
        return gain

    # -- linear analysis -------------------------------------------------------
    def loop(self, use_estimate: bool | None = None, gain_factor: float = 1.0) -> analysis.Loop:
        """The closed loop (steady-state filter) with the controller scaled by ``gain_factor``."""
        use_estimate = self.use_estimate if use_estimate is None else use_estimate
        state_gain = self.state_feedback_gain
        loop = analysis.closed_loop(self.model, gain_factor * self.controller,
                                    self.steady_state_filter[0], use_estimate,
                                    None if state_gain is None else gain_factor * state_gain)
        if self.reference_filter is not None:
            loop = analysis.with_reference_filter(loop, self.reference_filter)
        return loop

    def loop_matrix(self, gain_factor: float = 1.0) -> np.ndarray:
        """State matrix of the loop's states in the feedback (``loop_poles`` are its eigenvalues),
        affine in ``gain_factor`` (the pole map's root locus)."""
        loop = self.loop(gain_factor=gain_factor)
        return np.asarray(loop.system.A)[loop.loop_states, loop.loop_states]

    def loop_at_plant_input(self, gain_factor: float = 1.0) -> control.StateSpace:
        """Open loop L broken at the plant input (i_ref): plant, filter, controller and state
        feedback in series, sign included, so S = 1 / (1 + L) (for margins and |S|max)."""
        state_gain = self.state_feedback_gain
        comp = analysis.compensator(self.model, gain_factor * self.controller, self.steady_state_filter[0],
                                    self.use_estimate, None if state_gain is None else gain_factor * state_gain)
        return analysis.loop_at_plant_input(self.model, comp)

    @property
    def noise_variances(self) -> dict[str, float]:
        """Per-sample variances of the loop's noise inputs (``analysis.LOOP_INPUTS``)."""
        return dict(zip(("process_v", "process_i", "noise_x_v", "noise_i_v"), self.noise_sigma**2))

    def noise_rms(self, use_estimate: bool | None = None, gain_factor: float = 1.0) -> dict:
        """Steady-state RMS of x [m], i_ref [V] and i [A] driven by the plant's and sensors' noise."""
        return analysis.noise_rms(self.loop(use_estimate, gain_factor), self.noise_variances)

    @cached_property
    def displacement_floor_m(self) -> float:
        """Lower bound [m] on the RMS rotor displacement under *any* causal controller.

        Whatever the controller does with y_0 ... y_k, x_{k+1} = x_{k+1|k} + error,
        and the error is orthogonal to everything known at step k, so
        E[x_{k+1}^2] >= P_{k+1|k}[x, x]: the one-step prediction error of the
        Kalman filter that knows the plant's true noise (eq. 2 with the true Q
        and R), in steady state.  Without process noise and sensor lag it is
        sigma_x sqrt(exp(2 a T) - 1) ~ sigma_x sqrt(2 a T), a = sqrt(k_x / m):
        the price of the unstable pole (linear plant, eq. 3-4)."""
        sigma = self.noise_sigma
        Q = np.zeros((self.model.nstates, self.model.nstates))
        Q[1, 1], Q[2, 2] = sigma[0] ** 2, sigma[1] ** 2
        _, P = analysis.steady_state_kalman(self.model, Q, np.diag(sigma[2:] ** 2))
        return float(np.sqrt(P[0, 0]))

    def inputs_at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """Reference [m] and disturbance force [N] at times ``t_s`` [s]: square
        waves of period ``step_period_s`` (first half zero, second half on)."""
        on = (np.mod(t_s, self.step_period_s) >= 0.5 * self.step_period_s).astype(float)
        return self.reference_step_m * on, self.disturbance_step_n * on

    def with_changes(self, **changes) -> AxisSetup:
        """A copy with some fields changed; it keeps the model and the steady-state
        filter already solved when none of the fields they depend on changed
        (sweeps over controllers then solve the filter's Riccati equation once)."""
        new = replace(self, **changes)
        if not FILTER_FIELDS & changes.keys():
            for name in ("model", "steady_state_filter", "displacement_floor_m"):
                if name in self.__dict__:
                    new.__dict__[name] = self.__dict__[name]
        return new


class AxisSimulation:
    """Time simulation of an ``AxisSetup``: state, noise stream and traces.

    Each instance owns its random generator (seeded), so two simulations
    never share a stream; ``advance`` is safe to call from a worker thread
    while other simulations run on other threads.
    """

    columns = radial_axis_loop.TRACE_COLUMNS

    def __init__(self, setup: AxisSetup, seed: int = 0):
        self.setup = setup
        self.seed = seed
        self.sample_time_s = setup.rig.sample_time_s
        self.rng = np.random.default_rng(seed)
        rig, model = setup.rig, setup.model
        n = model.nstates
        self.plant = np.zeros(4)
        A, B = np.asarray(model.A), np.asarray(model.B)
        initial_P = np.diag([(10e-6) ** 2, (1e-3) ** 2, 0.1**2, (10e-6) ** 2][:n])
        self.filter = KalmanFilter(A, B[:, 0], model.C, setup.filter_Q, np.diag(setup.filter_R),
                                   np.zeros(n), initial_P)
        controller = setup.controller
        self.controller_matrices = tuple(np.ascontiguousarray(np.atleast_2d(np.asarray(M, dtype=float)))
                                    for M in (controller.A, controller.B, controller.C, controller.D))
        self.ctrl = np.zeros(self.controller_matrices[0].shape[0])
        self._state_gain = pad_vector(np.zeros(0) if setup.state_gain is None else setup.state_gain)
        self.plant_linear = self._padded_plant(A, B)
        self.physics = np.array([rig.equivalent_mass_kg, rig.force_factor_n_m2_per_a2, rig.i0_a,
                                  rig.delta0_m, np.cos(rig.pole_angle_rad), rig.amplifier_lag_s,
                                  rig.amplifier_gain_a_per_v, setup.sensor_lag_s, rig.sample_time_s,
                                  rig.position_sensor_gain_v_per_m, rig.current_sensor_gain_v_per_a])
        self.u_limit_v = rig.current_limit_a / rig.amplifier_gain_a_per_v
        self.step = 0
        self.status = radial_axis_loop.OK
        self._last_correction = None                   # (prior x̂, prior P, y, time) of the last sample
        self.tape = FilterTape(FilterModel.of_filter(self.filter, FILTER_TITLE, rig.sample_time_s,
                                                     self.STATE_LABELS[:n], MEASUREMENTS))
        self._reference_filter = None                  # (numerator, denominator, filter state)
        if setup.reference_filter is not None:
            transfer = control.ss2tf(setup.reference_filter)
            numerator, denominator = np.ravel(transfer.num[0][0]), np.ravel(transfer.den[0][0])
            state = np.zeros(max(numerator.size, denominator.size) - 1)
            self._reference_filter = (numerator, denominator, state)

    def retuned(self, setup: AxisSetup) -> AxisSimulation:
        """A simulation with new settings that carries on from this one's state
        (rotor, filter estimate and covariance, controller, time, noise stream),
        so a slider move changes the running experiment instead of restarting it.
        Parts whose size changed (filter order, controller order) start afresh."""
        new = AxisSimulation(setup)
        new.rng, new.step, new.plant[:] = self.rng, self.step, self.plant
        if new.filter.dim_x == self.filter.dim_x:
            new.filter.state[:], new.filter.P[:] = self.filter.state, self.filter.P
        if new.ctrl.shape == self.ctrl.shape:
            new.ctrl[:] = self.ctrl
        if (new._reference_filter is not None and self._reference_filter is not None
                and new._reference_filter[2].shape == self._reference_filter[2].shape):
            new._reference_filter[2][:] = self._reference_filter[2]
        return new

    @staticmethod
    def _padded_plant(A, B):
        """Exact discrete plant on (x, v, i, x_d); without a lag x_d is x."""
        n = A.shape[0]
        A4, Bu, Bf = np.zeros((4, 4)), np.zeros(4), np.zeros(4)
        A4[:n, :n], Bu[:n], Bf[:n] = A, B[:, 0], B[:, 1]
        if n == 3:
            A4[3, :3], Bu[3], Bf[3] = A[0], B[0, 0], B[0, 1]
        return A4, Bu, Bf

    @property
    def time_s(self) -> float:
        return self.step * self.setup.rig.sample_time_s

    def inputs(self, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """Reference [m] and disturbance force [N] for the next samples (``AxisSetup.inputs_at``)."""
        setup = self.setup
        if setup.reference_step_m == 0.0 and setup.disturbance_step_n == 0.0:
            return np.zeros(n_steps), np.zeros(n_steps)
        return setup.inputs_at((self.step + np.arange(n_steps)) * setup.rig.sample_time_s)

    def advance(self, n_steps: int) -> np.ndarray:
        """Run ``n_steps`` samples (fewer if the rotor touches down or diverges);
        return the trace array, columns ``radial_axis_loop.TRACE_COLUMNS``, with a
        leading time column [s]."""
        if self.status != radial_axis_loop.OK or n_steps <= 0:
            return np.empty((0, len(radial_axis_loop.TRACE_COLUMNS) + 1))
        reference, disturbance = self.inputs(n_steps)
        if self._reference_filter is not None:
            numerator, denominator, state = self._reference_filter
            reference, state[:] = scipy.signal.lfilter(numerator, denominator, reference, zi=state)
        noise = self.noise(n_steps)
        trace = np.empty((n_steps, len(radial_axis_loop.TRACE_COLUMNS) + 1))
        kf, setup = self.filter, self.setup
        rotor = radial_axis_loop.Rotor(state=self.plant, physics=self.physics, touchdown_m=setup.rig.touchdown_m)
        A, B_u, B_f = self.plant_linear
        linear_plant = radial_axis_loop.LinearPlant(nonlinear=setup.nonlinear, A=A, B_u=B_u, B_f=B_f)
        Ac, Bc, Cc, Dc = self.controller_matrices
        controller = DiscreteController(state=self.ctrl, A=Ac, B=Bc, C=Cc, D=Dc)
        feedback = radial_axis_loop.Feedback(use_estimate=setup.use_estimate, state_gain=self._state_gain,
                                             u_limit_v=self.u_limit_v)

        def run(first: int, last: int) -> tuple[int, int]:
            return radial_axis_loop.run(
                last - first, self.step + first, rotor, linear_plant, kf.arrays(), controller, feedback,
                radial_axis_loop.Inputs(reference_m=reference[first:last], disturbance_n=disturbance[first:last]),
                radial_axis_loop.Noise(draws=noise[first:last], sigma=setup.noise_sigma), trace[first:last])

        prior = kf.state.copy(), kf.P.copy()
        status, done = run(0, n_steps)
        y = self.measurements(trace[:done], noise[:done])
        # a single step (the inspector's) keeps the prior
        self._last_correction = (*prior, y[0], trace[0, 0]) if n_steps == 1 else None
        column = {name: 1 + j for j, name in enumerate(radial_axis_loop.TRACE_COLUMNS)}
        truth = np.full((done, kf.dim_x), np.nan)      # the lagged sensor's state x_d is not traced
        truth[:, :3] = trace[:done, [column["x_true_m"], column["velocity_true_m_per_s"], column["current_a"]]]
        self.tape.record(self.step, *prior, trace[:done, 0], trace[:done, column["current_reference_v"]], y, truth)
        self.step += done
        self.status = status
        return trace[:done]

    def measurements(self, trace: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The filter's measurements y (N, 2) [V] of these trace rows and noise draws (eq. 1: the
        traced measured position, the true current plus the current sensor's noise)."""
        return np.column_stack([trace[:, 2] * self.physics[9],
                                trace[:, 5] * self.physics[10] + self.setup.noise_sigma[3] * noise[:, 3]])

    def filter_tape(self) -> FilterTape:
        """The record of the filter's inputs (``estimators.filter_history``): the filter debugger's."""
        return self.tape

    STATE_LABELS = (("position x", "m"), ("velocity v", "m/s"), ("coil current i", "A"),
                    ("sensed position x_d (lag)", "m"))

    def filter_state(self) -> dict | None:
        """The linear Kalman filter (eq. 2) at the sample of the last advance(1): its corrected estimate x̂ and P,
        the gain K, the innovation and its predicted σ = √S (see ``Simulation.filter_state``)."""
        if self._last_correction is None:
            return None
        x_prior, P_prior, y, time_s = self._last_correction
        n, kf = self.filter.dim_x, self.filter
        step = correction(x_prior[:n], P_prior[:n, :n], kf.C[:, :n], kf.R_diag, y)
        return {"title": FILTER_TITLE, "time_s": float(time_s),
                "states": self.STATE_LABELS[:n], "x": step["x"], "P": step["P"],
                "measurements": MEASUREMENTS, "K": step["K"], "innovation": step["innovation"],
                "innovation_sigma": np.sqrt(np.diag(step["S"]))}

    def noise(self, n_steps: int) -> np.ndarray:
        """The next ``n_steps`` x 4 standard normal draws (process v, process i,
        sensor x, sensor i).  Single precision: half the cost of double, and
        ample for noise."""
        return self.rng.standard_normal((n_steps, 4), dtype=np.float32)

    def status_message(self) -> str:
        """What happened, in words, for a stopped simulation ('' while running)."""
        t_ms = self.time_s * 1e3
        if self.status == radial_axis_loop.TOUCHDOWN:
            return (f"Touchdown at t = {t_ms:.1f} ms: the rotor left the air gap "
                    f"(|x| >= {self.setup.rig.touchdown_m * 1e6:.0f} µm). The loop is unstable, saturated "
                    "or cannot hold the load at these settings (a filter without a disturbance state "
                    "leaves estimated feedback without integral action against a force); reset.")
        if self.status == radial_axis_loop.DIVERGED:
            return (f"Diverged at t = {t_ms:.1f} ms: the simulation produced non-finite values. "
                    "Reset with other settings.")
        return ""
