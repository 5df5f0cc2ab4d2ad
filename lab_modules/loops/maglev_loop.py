"""One maglev experiment (paper 004 §3.1-3.2): plant, sensor, EKF and a
controller, stepped at dt = 1 ms by a compiled kernel.

Per sample k (the structure of the paper's Fig. 3.1 and App. F):

1. sensor      y_k = x1 + v_k,  v_k ~ N(0, sigma^2)                  (eq. 2.34, 3.2)
2. filter      update with y_k (continuous-discrete EKF, eq. 2.40-2.42)
3. control     u_k from the estimate (feedback linearisation, eq. 2.21-2.30)
               or from y_k (lead-lag baseline)
4. plant       RK4 over dt with u_k held (eq. 2.10), then process noise on
               x2 and x3 with the spectral densities of ``plant_Q``
5. filter      propagate to k+1 with u_k (eq. 2.43-2.45); the continuous-time
               filter instead integrates its Kalman-Bucy equations with y_k held

The simulation stops (``status_message``) when the ball strikes the magnet,
drops out of the field or the filter's numbers stop being finite.  The kernel
takes named bundles: ``Ball``, ``MaglevFilter`` and ``MaglevControl``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

import control
import numba
import numpy as np
import scipy.linalg

from lab_modules import analysis
from lab_modules.controllers.feedback_linearisation import GUARD_CURRENT_A, feedback_gain, linearising_control
from lab_modules.controllers.lead_lag import LEAD_LAG, LeadLag
from lab_modules.controllers.pid import DiscreteController, controller_step
from lab_modules.estimators import continuous_discrete_ekf as cd
from lab_modules.estimators.continuous_discrete_ekf import bucy_step, propagate, update
from lab_modules.estimators.filter_history import FilterTape
from lab_modules.estimators.kalman import correction
from lab_modules.plants.maglev_ball import TABLE_3_1, MaglevPlant, rk4_step

OK, STRUCK_MAGNET, FELL, DIVERGED = 0, 1, 2, 3
STATUS_TEXT = {
    STRUCK_MAGNET: "Stopped: the ball struck the magnet (gap below {:.0f} mm).",
    FELL: "Stopped: the ball fell out of the magnet's reach (gap above {:.0f} mm).",
    DIVERGED: "Stopped: the filter diverged (its estimate or covariance is no longer finite).",
}
#: Touchdown limits (not in the paper): the ball (19 mm diameter, §3.3) hits
#: the coil face well before x1 = 0; below 2 mm the force law eq. 2.7 is no
#: longer meaningful.  30 mm is twice the operating gap, where the magnet can
#: no longer lift the ball with the currents of §3 (x3 ~ 2 A by eq. 2.14).
MIN_GAP_M, MAX_GAP_M = 2e-3, 30e-3

CONTROLLERS = ("linearising", "lead-lag")
FILTERS = ("continuous-discrete", "continuous-time", "continuous-time-Rdt")

TRACE_COLUMNS = (
    "reference_m", "x_true_m", "x_measured_m", "x_estimated_m", "x_sigma_m",
    "velocity_true_m_per_s", "velocity_estimated_m_per_s", "velocity_sigma_m_per_s",
    "current_true_a", "current_estimated_a", "coil_voltage_v",
    "position_error_m", "velocity_error_m_per_s", "zero", "innovation_m", "nis", "guarded",
)
COLUMN = {name: i for i, name in enumerate(TRACE_COLUMNS)}


# -- references (§3.1.2-3.1.3, §3.7) -----------------------------------------------

@dataclass(frozen=True)
class Reference:
    """A reference trajectory y_R(t) with its first three derivatives.

    kind: "step" (``amplitude_m`` added at ``step_time_s``), "sine" or "square"
    (``amplitude_m`` at ``frequency_rad_s``), around ``base_m``.  Steps and
    square waves have no derivatives; ``smoothing`` says what the controller
    gets instead: "zeroed" (the paper's choice, §3.1.2: y_R' = y_R'' = y_R''' = 0
    while y_R jumps) or "prefilter" (the raw reference through
    w^4 / (s + w)^4, whose states are exactly y_R ... y_R''').
    """

    kind: str = "step"
    amplitude_m: float = 2e-3
    frequency_rad_s: float = 10.0
    base_m: float = 0.0148
    step_time_s: float = 0.75
    smoothing: str = "zeroed"
    prefilter_bandwidth_rad_s: float = 30.0

    def raw(self, t: np.ndarray) -> np.ndarray:
        """y_R(t) before any smoothing [m]."""
        if self.kind == "step":
            return self.base_m + self.amplitude_m * (t >= self.step_time_s)
        if self.kind == "square":
            return self.base_m + self.amplitude_m * np.where(np.sin(self.frequency_rad_s * t) >= 0, 1.0, -1.0)
        return self.base_m + self.amplitude_m * np.sin(self.frequency_rad_s * t)

    def prefilter(self, sample_time_s: float) -> control.StateSpace:
        """w^4/(s+w)^4 with state (y, y', y'', y'''), discretised exactly for a held input (ZOH)."""
        w = self.prefilter_bandwidth_rad_s
        A = np.diag(np.ones(3), k=1)
        A[3] = [-w**4, -4 * w**3, -6 * w**2, -4 * w]
        B = np.array([[0.0], [0.0], [0.0], [w**4]])
        return control.c2d(control.ss(A, B, np.eye(4), np.zeros((4, 1))), sample_time_s, method="zoh")


class ReferenceGenerator:
    """Streams (y_R, y_R', y_R'', y_R''') sample by sample (rows of an (n, 4) array)."""

    def __init__(self, reference: Reference, sample_time_s: float):
        self.reference = reference
        self.dt = sample_time_s
        self.k = 0
        self.filtered = reference.kind != "sine" and reference.smoothing == "prefilter"
        if self.filtered:
            d = reference.prefilter(sample_time_s)
            self.Ad, self.Bd = np.asarray(d.A), np.asarray(d.B)[:, 0]
            self.state = np.array([reference.raw(np.array([0.0]))[0], 0.0, 0.0, 0.0])

    def next(self, n: int) -> np.ndarray:
        t = (self.k + np.arange(n)) * self.dt
        self.k += n
        ref = self.reference
        raw = ref.raw(t)
        out = np.zeros((n, 4))
        if ref.kind == "sine":
            w, a = ref.frequency_rad_s, ref.amplitude_m
            out[:, 0] = raw
            out[:, 1] = a * w * np.cos(w * t)
            out[:, 2] = -a * w**2 * np.sin(w * t)
            out[:, 3] = -a * w**3 * np.cos(w * t)
        elif self.filtered:
            for i in range(n):
                out[i] = self.state
                self.state = self.Ad @ self.state + self.Bd * raw[i]
        else:
            out[:, 0] = raw
        return out


# -- the experiment ----------------------------------------------------------------

def table_3_1_q() -> np.ndarray:
    """Q(t) of Table 3.1: 0.025 diag(0, 1, 1) (simulations, §3.1-3.2)."""
    return 0.025 * np.diag([0.0, 1.0, 1.0])


def hardware_q() -> np.ndarray:
    """Q(t) of eq. 3.4: diag(1e-4, 0.75e-7, 1e-8) (tuned on hardware data, §3.5.2)."""
    return np.diag([1e-4, 0.75e-7, 1e-8])


def preset_q(values: dict) -> np.ndarray:
    """Q(t) [m²/s, m²/s³, A²/s] from an exercise's ``q_preset`` ("table_3.1", "eq_3.4") or, for any
    other preset, from its ``q_position``, ``q_velocity`` and ``q_current`` values."""
    if values["q_preset"] == "table_3.1":
        return table_3_1_q()
    if values["q_preset"] == "eq_3.4":
        return hardware_q()
    return np.diag([values["q_position"], values["q_velocity"], values["q_current"]])


@dataclass(frozen=True)
class MaglevSetup:
    """Everything one maglev experiment needs (SI units; Table 3.1 defaults).

    ``plant`` is the model the filter and the controller use; ``true_plant``
    (default: the same) is the simulated ball and coil."""

    plant: MaglevPlant = TABLE_3_1
    true_plant: MaglevPlant | None = None
    poles_rad_per_s: tuple[float, float, float] = (-60.0, -80.0, -100.0)
    controller: str = "linearising"
    lead_lag: LeadLag = LEAD_LAG
    filter: str = "continuous-discrete"
    filter_Q: np.ndarray = field(default_factory=table_3_1_q)
    plant_Q: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    sensor_noise_m: float = 1e-3
    initial_state: tuple[float, float, float] = (0.0148, 0.0, 0.89409)
    initial_estimate: tuple[float, float, float] = (0.014367, 0.0, 0.9388)
    initial_covariance: float = 0.085
    reference: Reference = Reference()
    filter_substeps: int = 1

    def with_changes(self, **changes) -> MaglevSetup:
        return replace(self, **changes)

    @property
    def gain(self) -> np.ndarray:
        return feedback_gain(self.poles_rad_per_s)


class Ball(NamedTuple):
    """The simulated ball and coil (eq. 2.10) and its sensor."""

    state: np.ndarray             # (3,) true gap x1 [m], velocity x2 [m/s], coil current x3 [A], in place
    constants: np.ndarray         # (5,) the true plant's m [kg], L_c [H], R_c [Ω], C [N m²/A²], g [m/s²]
    process_density: np.ndarray   # (3,) white process noise densities on x1, x2, x3 [m²/s, m²/s³, A²/s]
    sensor_variance_m2: float     # variance of the position sensor's white noise [m²] (eq. 3.2)


class MaglevFilter(NamedTuple):
    """The EKF (``FILTERS``: continuous-discrete, eq. 2.40-2.45, or continuous-time) on the
    model's constants; states (x1 [m], x2 [m/s], x3 [A])."""

    kind: int              # index in ``FILTERS``: 0 continuous-discrete, 1 continuous-time, 2 with R_c = r dt
    x_hat: np.ndarray      # (3,) estimate, in place [m, m/s, A]
    P: np.ndarray          # (3, 3) error covariance, in place [state unit x state unit]
    Q: np.ndarray          # (3, 3) process noise spectral densities [m²/s, m²/s³, A²/s on the diagonal]
    R_m2: float            # measurement variance r [m²]
    constants: np.ndarray  # (5,) the model's m [kg], L_c [H], R_c [Ω], C [N m²/A²], g [m/s²]
    substeps: int          # RK4 steps per sample of the continuous-discrete propagation


class MaglevControl(NamedTuple):
    """The controller (``CONTROLLERS``): feedback linearisation on the estimate, or the lead-lag
    on the measured gap around the equilibrium voltage."""

    kind: int                      # index in ``CONTROLLERS``: 0 linearising, 1 lead-lag
    gain: np.ndarray               # (3,) k of eq. 2.30 [1/s³, 1/s², 1/s]
    lead_lag: DiscreteController   # e = y - y_R [m] -> coil voltage [V]
    u0_v: float                    # equilibrium coil voltage added to the lead-lag's output [V]


@numba.njit(nogil=True, cache=True)
def run(n_steps, t0, dt, ball, ekf, control, refs, noise, trace):
    """Advance the loop by up to n_steps samples (module docstring); returns (steps done, status).

    t0 : time of the first sample [s]; dt : sample time [s].
    ball : ``Ball``, the true plant (its constants ``p_true``) and sensor, stepped in place.
    ekf : ``MaglevFilter``, the filter on the model's constants ``p``, in place.
    control : ``MaglevControl``, the controller (the lead-lag's state in place).
    refs : (n_steps, 4) y_R, y_R', y_R'', y_R''' [m, m/s, m/s², m/s³].
    noise : (n_steps, 3) standard normal draws: sensor, velocity, current.
    trace : (n_steps, 1 + len(TRACE_COLUMNS)) output."""
    # every field read once, before the loop (a bundle's array read per sample costs a reference count)
    x, p_true, plant_q, sensor_variance = ball.state, ball.constants, ball.process_density, ball.sensor_variance_m2
    filter_kind, x_hat, P, Q, r, p, substeps = ekf.kind, ekf.x_hat, ekf.P, ekf.Q, ekf.R_m2, ekf.constants, ekf.substeps
    controller, k, u0, lead_lag = control.kind, control.gain, control.u0_v, control.lead_lag
    xc, Ac, Bc, Cc, Dc = lead_lag.state, lead_lag.A, lead_lag.B, lead_lag.C, lead_lag.D
    gain = np.empty(3)
    x_next = np.empty(3)
    sigma = np.sqrt(sensor_variance)
    sq_v, sq_i = np.sqrt(plant_q[1] * dt), np.sqrt(plant_q[2] * dt)
    xc_next = np.empty(xc.shape[0])
    for step in range(n_steps):
        y = x[0] + sigma * noise[step, 0]
        innovation, s = 0.0, P[0, 0] + r
        if filter_kind == 0:
            innovation, s = update(x_hat, P, y, r, gain)
        guarded = False
        if controller == 0:
            u, guarded = linearising_control(x_hat, refs[step], k, p)
        else:
            u = controller_step(y - refs[step, 0], u0, np.inf, xc, Ac, Bc, Cc, Dc, xc_next)
        row = trace[step]
        row[0] = t0 + step * dt
        row[1] = refs[step, 0]
        row[2], row[3], row[4], row[5] = x[0], y, x_hat[0], np.sqrt(max(P[0, 0], 0.0))
        row[6], row[7], row[8] = x[1], x_hat[1], np.sqrt(max(P[1, 1], 0.0))
        row[9], row[10], row[11] = x[2], x_hat[2], u
        row[12], row[13], row[14] = x[0] - x_hat[0], x[1] - x_hat[1], 0.0
        row[15], row[16], row[17] = innovation, innovation * innovation / s, 1.0 if guarded else 0.0
        rk4_step(x, u, p_true, dt, x_next)
        x[0] = x_next[0]
        x[1] = x_next[1] + sq_v * noise[step, 1]
        x[2] = x_next[2] + sq_i * noise[step, 2]
        if filter_kind == 0:
            propagate(x_hat, P, u, p, Q, dt, substeps)
        else:
            bucy_step(x_hat, P, u, y, p, Q, r if filter_kind == 1 else r * dt, dt)
        if not (np.isfinite(x_hat[0]) and np.isfinite(x_hat[1]) and np.isfinite(x_hat[2])
                and np.isfinite(P[0, 0]) and np.isfinite(P[1, 1]) and np.isfinite(P[2, 2])):
            return step + 1, 3
        if not x[0] >= MIN_GAP_M:
            return step + 1, 1
        if x[0] > MAX_GAP_M:
            return step + 1, 2
    return n_steps, 0


class MaglevSimulation:
    """The scope's simulation (duck-typed ``Simulation`` of the exercise framework)."""

    def __init__(self, setup: MaglevSetup, seed: int = 0):
        self.setup = setup
        self.sample_time_s = setup.plant.sample_time_s
        self.columns = TRACE_COLUMNS
        self.rng = np.random.default_rng(seed)
        self.references = ReferenceGenerator(setup.reference, self.sample_time_s)
        self.x = np.array(setup.initial_state, dtype=float)
        self.x_hat = np.array(setup.initial_estimate, dtype=float)
        self.P = setup.initial_covariance * np.eye(3)
        self.constants = setup.plant.constants()
        self.true_constants = (setup.true_plant or setup.plant).constants()
        self.k = setup.gain
        discrete = setup.lead_lag.discrete(self.sample_time_s)
        self.lead_lag = tuple(np.ascontiguousarray(np.atleast_2d(np.asarray(M, dtype=float)))
                              for M in (discrete.A, discrete.B, discrete.C, discrete.D))
        self.xc = np.zeros(self.lead_lag[0].shape[0])
        self.u0 = setup.plant.equilibrium_voltage_v(setup.reference.base_m)
        # the kernel's bundles over these arrays, made once (a call of the kernel may be short)
        self._ball = Ball(state=self.x, constants=self.true_constants,
                          process_density=np.diag(setup.plant_Q).astype(float),
                          sensor_variance_m2=setup.sensor_noise_m**2)
        self._filter = MaglevFilter(kind=FILTERS.index(setup.filter), x_hat=self.x_hat, P=self.P,
                                    Q=np.asarray(setup.filter_Q, dtype=float), R_m2=setup.sensor_noise_m**2,
                                    constants=self.constants, substeps=setup.filter_substeps)
        Ac, Bc, Cc, Dc = self.lead_lag
        self._control = MaglevControl(kind=CONTROLLERS.index(setup.controller), gain=self.k,
                                      lead_lag=DiscreteController(state=self.xc, A=Ac, B=Bc, C=Cc, D=Dc),
                                      u0_v=self.u0)
        self.steps = 0
        self.status = OK
        self.guarded_steps = 0                        # controller steps clamped by the singularity guard
        self._last_correction = None                   # (prior x̂, prior P, y, time) of the last sample
        self.filter_title = f"{setup.filter} EKF of the maglev ball (paper 004 §2.5)"
        self.tape = None if setup.filter != FILTERS[0] else FilterTape(cd.history_model(
            self.filter_title, self.sample_time_s, self.constants, setup.filter_Q, setup.sensor_noise_m**2,
            setup.filter_substeps, fixed_interval=True))

    def filter_tape(self) -> FilterTape | None:
        """The continuous-discrete filter's record (``estimators.filter_history``); None: it corrects continuously."""
        return self.tape

    def advance(self, n_steps: int) -> np.ndarray:
        if self.status != OK or n_steps <= 0:
            return np.zeros((0, 1 + len(TRACE_COLUMNS)))
        refs = self.references.next(n_steps)
        noise = self.rng.standard_normal((n_steps, 3))
        trace = np.empty((n_steps, 1 + len(TRACE_COLUMNS)))

        def part(first: int, last: int) -> tuple[int, int]:
            return run(last - first, (self.steps + first) * self.sample_time_s, self.sample_time_s, self._ball,
                       self._filter, self._control, refs[first:last], noise[first:last], trace[first:last])

        prior = self.x_hat.copy(), self.P.copy()
        done, self.status = part(0, n_steps)
        rows = trace[:done]
        y = rows[:, 1 + COLUMN["x_measured_m"]]
        self._last_correction = (*prior, y[:1], rows[0, 0]) if n_steps == 1 else None   # the inspector's step
        if self.tape is not None:
            truth = rows[:, [1 + COLUMN[name] for name in ("x_true_m", "velocity_true_m_per_s", "current_true_a")]]
            self.tape.record(self.steps, *prior, rows[:, 0], rows[:, 1 + COLUMN["coil_voltage_v"]], y, truth)
        self.steps += done
        self.guarded_steps += int(np.sum(trace[:done, 1 + COLUMN["guarded"]]))
        return trace[:done]

    def filter_state(self) -> dict | None:
        """The continuous-discrete EKF (eq. 2.40-2.42, H = [1 0 0]) at the sample of the last advance(1): corrected
        x̂ and P, gain K, innovation and √S.  The continuous-time filters correct continuously
        (no sample gain): their x̂ and P only."""
        if self._last_correction is None:
            return None
        x_prior, P_prior, y, time_s = self._last_correction
        state = {"title": self.filter_title, "time_s": float(time_s), "states": cd.STATES,
                 "measurements": cd.MEASUREMENTS}
        if self.setup.filter != FILTERS[0]:
            return {**state, "x": self.x_hat.copy(), "P": self.P.copy(), "K": None, "innovation": None,
                    "innovation_sigma": None}
        step = correction(x_prior, P_prior, [[1.0, 0.0, 0.0]], [self.setup.sensor_noise_m**2], y)
        return {**state, "x": step["x"], "P": step["P"], "K": step["K"], "innovation": step["innovation"],
                "innovation_sigma": np.sqrt(np.diag(step["S"]))}

    def status_message(self) -> str:
        if self.status == OK:
            return ""
        text = STATUS_TEXT[self.status].format(MIN_GAP_M * 1e3 if self.status == STRUCK_MAGNET
                                               else MAX_GAP_M * 1e3)
        if self.guarded_steps and self.setup.controller == "linearising":
            text += (f" At t = {self.steps * self.sample_time_s:.3f} s, after {self.guarded_steps} guarded controller "
                     f"step(s): the estimated current x̂3 fell to the guard's {GUARD_CURRENT_A * 1e3:.0f} mA, where "
                     "eq. 2.23 asks for a voltage growing as 1/x̂3. Noisy estimates times large gains k (fast "
                     "poles, or the first samples while P0 is large) drove it there: less sensor noise or "
                     "slower poles keep x̂3 away from 0.")
        return text

    def run(self, duration_s: float) -> dict[str, np.ndarray]:
        """Whole run as columns (``time_s`` plus ``TRACE_COLUMNS``)."""
        trace = self.advance(round(duration_s / self.sample_time_s))
        return {name: trace[:, i] for i, name in enumerate(("time_s",) + TRACE_COLUMNS)}


# -- a lab recording (§3.4-3.5) ------------------------------------------------------

def record_lead_lag_run(duration_s: float = 6.0, still_s: float = 1.0, sensor_noise_m: float = 3.4e-6,
                        plant_Q=None, seed: int = 0, plant: MaglevPlant = TABLE_3_1):
    """A recording like the paper's (Fig. 3.25): the lead-lag controller holds the ball at 14.8 mm.

    For the first ``still_s`` the ball rests on the positioning tool (§3.3,
    Fig. 3.18) at 14.8 mm with the coil at its equilibrium voltage: the
    position is constant and the samples show the sensor noise alone (§3.4,
    eq. 3.3).  Then the tool is withdrawn and the lead-lag controller
    levitates the ball, disturbed by white process noise of spectral
    densities ``plant_Q`` (default ``RECORDING_PLANT_Q``).  Returns a
    ``recordings.Recording`` whose metadata states the noise used.
    """
    from lab_modules.recordings import Recording

    plant_Q = RECORDING_PLANT_Q if plant_Q is None else np.asarray(plant_Q, dtype=float)
    gap = TABLE_3_1.operating_gap_m
    current = plant.equilibrium_current_a(gap)
    setup = MaglevSetup(plant=plant, controller="lead-lag", plant_Q=plant_Q, sensor_noise_m=sensor_noise_m,
                        initial_state=(gap, 0.0, current), initial_estimate=(gap, 0.0, current),
                        initial_covariance=1e-6, filter_Q=hardware_q(),
                        reference=Reference(kind="step", amplitude_m=0.0, base_m=gap))
    dt = plant.sample_time_s
    rng = np.random.default_rng(seed)
    n_still = round(still_s / dt)
    sim = MaglevSimulation(setup, seed=int(rng.integers(2**31)))
    levitated = sim.run(duration_s - still_s)
    if sim.status_message():
        raise RuntimeError(sim.status_message())
    n = n_still + levitated["time_s"].size
    still_measured = gap + sensor_noise_m * rng.standard_normal(n_still)
    metadata = {
        "source": "lab simulation: lead-lag controlled ball, paper 004 Table 3.1 plant",
        "sensor_noise_mm": f"{sensor_noise_m * 1e3:g}",
        "still_segment_s": f"0 - {still_s:g} (ball resting on the positioning tool)",
        "plant_process_noise_density": (f"velocity {plant_Q[1, 1]:g} m^2/s^3, "
                                        f"current {plant_Q[2, 2]:g} A^2/s"),
        "seed": str(seed),
    }
    return Recording(
        time_s=np.arange(n) * dt,
        reference_m=np.full(n, gap),
        measured_m=np.concatenate([still_measured, levitated["x_measured_m"]]),
        coil_voltage_v=np.concatenate([np.full(n_still, plant.equilibrium_voltage_v(gap)),
                                       levitated["coil_voltage_v"]]),
        metadata=metadata, name="lab recording")


#: Process noise of the shipped recording (not in the paper): white force
#: noise of density 2e-4 m^2/s^3 makes the ball wander by about 50 µm RMS
#: under the lead-lag controller, fifteen times the sensor noise, like the
#: visible wandering of the hardware's recording (Fig. 3.25); 1e-8 A^2/s on
#: the current is eq. 3.4's Q_33.
RECORDING_PLANT_Q = np.diag([0.0, 2e-4, 1e-8])


# -- the loop linearised at the operating point, broken at the plant input (margins, |S|max) -------
def state_feedback_gain(setup: MaglevSetup) -> np.ndarray:
    """du/dx_hat of the feedback-linearising control (eq. 2.23, 2.30) at the equilibrium at the
    reference's base gap (reference at rest): central differences, steps 1e-6 of each state's scale."""
    p, gap = setup.plant.constants(), setup.reference.base_m
    x0 = np.array([gap, 0.0, setup.plant.equilibrium_current_a(gap)])
    reference = np.array([gap, 0.0, 0.0, 0.0])
    steps = 1e-6 * np.array([gap, 1.0, x0[2]])
    gain = np.empty(3)
    for j in range(3):
        e = np.zeros(3)
        e[j] = steps[j]
        gain[j] = (linearising_control(x0 + e, reference, setup.gain, p)[0]
                   - linearising_control(x0 - e, reference, setup.gain, p)[0]) / (2 * steps[j])
    return gain


def _discrete_noise(F: np.ndarray, Q: np.ndarray, dt: float) -> np.ndarray:
    """Q_d = integral_0^dt e^{F s} Q e^{F^T s} ds (Van Loan): what eq. 2.45 adds to P over dt."""
    n = F.shape[0]
    M = scipy.linalg.expm(np.block([[-F, Q], [np.zeros((n, n)), F.T]]) * dt)
    Phi = M[n:, n:].T
    return Phi @ M[:n, n:]


def loop_at_plant_input(setup: MaglevSetup) -> control.StateSpace:
    """Open loop L broken at the coil voltage (S = 1 / (1 + L)), everything linearised at the
    equilibrium at the reference's base gap (eq. 2.13-2.14), plant (the true one) by a zero-order
    hold at dt.  The lead-lag acts on the measured gap; feedback linearisation is the state
    feedback du/dx_hat (``state_feedback_gain``) on the filter's steady state at that point:
    continuous-discrete (eq. 2.40-2.45: correction, control, propagation over dt) or the
    continuous-time filter (Kalman-Bucy gain of the continuous Riccati equation, its
    equations held over dt with u and y, the control read before the step)."""
    dt, gap = setup.plant.sample_time_s, setup.reference.base_m
    true = setup.true_plant or setup.plant
    plant = control.c2d(true.linear_model(gap), dt, "zoh")
    if setup.controller == "lead-lag":
        compensator = setup.lead_lag.discrete(dt)            # u = u0 + C(z) (y - y_R)
        return analysis.loop_at_plant_input(plant, compensator)
    model = setup.plant.linear_model(gap)
    F, B, H = (np.asarray(M) for M in (model.A, model.B, model.C))
    r, gain = setup.sensor_noise_m ** 2, state_feedback_gain(setup)
    Q = np.asarray(setup.filter_Q, dtype=float)
    if setup.filter == "continuous-discrete":
        discrete = control.c2d(model, dt, "zoh")
        Ad, Bd = np.asarray(discrete.A), np.asarray(discrete.B)
        P = scipy.linalg.solve_discrete_are(Ad.T, H.T, _discrete_noise(F, Q, dt), np.array([[r]]))
        K = P @ H.T / (H @ P @ H.T + r)

        def step(x_p, y):
            x_hat = x_p + K[:, 0] * (y[0] - x_p[0])
            u = gain @ x_hat
            return Ad @ x_hat + Bd[:, 0] * u, np.array([u])
    else:
        r_c = r if setup.filter == "continuous-time" else r * dt
        P = scipy.linalg.solve_continuous_are(F.T, H.T, Q, np.array([[r_c]]))
        Kc = P @ H.T / r_c
        held = control.c2d(control.ss(F - Kc @ H, np.hstack([B, Kc]), np.eye(3), np.zeros((3, 2))), dt, "zoh")
        Af, Bf = np.asarray(held.A), np.asarray(held.B)

        def step(x_hat, y):
            u = gain @ x_hat
            return Af @ x_hat + Bf[:, 0] * u + Bf[:, 1] * y[0], np.array([u])
    return analysis.loop_at_plant_input(plant, analysis.state_space_from_step(step, 3, 1, dt))
