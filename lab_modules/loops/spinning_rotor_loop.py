"""The flexible rotor's bearing at speed in closed loop, both planes at once.

The plant is ``plants.spinning_rotor``'s complex model (r = x + i y: the x-z plane
in the real part, the y-z plane in the imaginary part); the controller is the
paper's PID (000 §IV) in each plane, on the measured position or on the rigid-model
Kalman filter's estimate (eq. 2), the same in both planes, so one real compensator
closes the complex loop.  Discretised with a zero-order hold at the DSP's T = 50 µs
for each speed; everything here is linear algebra on the closed loop's complex state
matrix: its eigenvalues (Campbell diagram, damping, stability against speed), its
response to the unbalance's forward synchronous force, and its time simulation with
the speed held or ramped (run-up).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg

from lab_modules.analysis import participation, z_to_s
from lab_modules.loops.flexible_rotor_loop import kalman_compensator, pid_compensator
from lab_modules.plants.radial_bearing import RIG, BearingAxis
from lab_modules.plants.spinning_rotor import SpinningPlant, rad_s, whirl_by_mode

#: Inputs and outputs of ``LoopAtSpeed`` (complex: x-z plane real, y-z plane imaginary).
LOOP_INPUTS = ("reference_m", "force_n", "noise_position_v", "noise_current_v")
LOOP_OUTPUTS = ("sensor_reading_m", "r_bearing_m", "r_sensor_m", "current_a", "innovation_m")


@dataclass(frozen=True)
class Compensator:
    """A real discrete compensator: inputs (y_position [V], y_current [V], r [m]); outputs
    (i_ref [V], the filter's position innovation y_position - K_mx x_p [V]); states A's."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray


def observed_compensator(controller: control.StateSpace, model: control.StateSpace, kalman_gain: np.ndarray,
                         reads_estimate: bool) -> Compensator:
    """The PID on the filter's estimate (``kalman_compensator``: states x_p, x_c) or on the
    measurement (``pid_compensator``) with the same filter watching (states x_c, x_p: its
    prediction x_p+ = A (x_p + K (y - C x_p)) + B u with the applied u, eq. 2); either way the
    second output is the filter's position innovation."""
    Am, Bm, Cm = (np.asarray(M) for M in (model.A, model.B, model.C))
    K = np.asarray(kalman_gain)
    n = Am.shape[0]
    take_y = np.hstack([np.eye(2), np.zeros((2, 1))])          # (y_position, y_current) of the inputs
    if reads_estimate:
        c = kalman_compensator(controller, model, K)
        A, B, Cu, Du = (np.atleast_2d(np.asarray(M)) for M in (c.A, c.B, c.C, c.D))
        prediction = np.hstack([np.eye(n), np.zeros((n, A.shape[0] - n))])
    else:
        c = pid_compensator(controller)
        Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(M)) for M in (c.A, c.B, c.C, c.D))
        nc = Ac.shape[0]
        Bu = Bm[:, :1]
        A = np.block([[Ac, np.zeros((nc, n))], [Bu @ Cc, Am @ (np.eye(n) - K @ Cm)]])
        B = np.vstack([Bc, Am @ K @ take_y + Bu @ Dc])
        Cu, Du = np.hstack([Cc, np.zeros((1, n))]), Dc
        prediction = np.hstack([np.zeros((n, nc)), np.eye(n)])
    C_innovation = -Cm[:1] @ prediction                        # nu = y_position - C_x x_p
    D_innovation = take_y[:1]
    return Compensator(A, B, np.vstack([Cu, C_innovation]), np.vstack([Du, D_innovation]))


@dataclass(frozen=True)
class LoopAtSpeed:
    """The discrete closed loop at one or more speeds: z+ = A z + B u, y = C z + D u (complex),
    inputs ``LOOP_INPUTS``, outputs ``LOOP_OUTPUTS`` in SI units; the plant's states come first.
    ``A`` and ``B`` carry a leading axis over ``speeds_rpm``."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    speeds_rpm: np.ndarray
    n_modes: int


def discretised(plant: SpinningPlant, speeds_rpm, rig: BearingAxis = RIG) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order hold of the plant at each speed: A_d, B_d stacked over the speeds, the
    blocks of expm([[A(Omega), B], [0, 0]] T) (one stacked expm)."""
    speeds = rad_s(np.atleast_1d(speeds_rpm))
    n, m = plant.B.shape
    augmented = np.zeros((len(speeds), n + m, n + m), dtype=complex)
    augmented[:, :n, :n] = plant.A0[None] + speeds[:, None, None] * plant.A1[None]
    augmented[:, :n, n:] = plant.B
    step = scipy.linalg.expm(augmented * rig.sample_time_s)
    return step[:, :n, :n], step[:, :n, n:]


def closed_loop_at_speed(plant: SpinningPlant, compensator: Compensator, speeds_rpm,
                         rig: BearingAxis = RIG, discrete: tuple[np.ndarray, np.ndarray] | None = None) -> LoopAtSpeed:
    """Plant (discretised at each speed, or ``discrete`` from ``discretised``) and compensator
    closed: with y = C_y z_p + noise, u = C_c z_c + D_c (y, r), z_c+ = A_c z_c + B_c (y, r),
    z_p+ = A_d z_p + B_u u + B_f f."""
    speeds = np.atleast_1d(np.asarray(speeds_rpm, dtype=float))
    Ad, Bd = discretised(plant, speeds, rig) if discrete is None else discrete
    Bu, Bf = Bd[:, :, :1], Bd[:, :, 1:2]
    Cy = plant.C[[0, 3]]                                       # (K_mx x_d, K_mi i) [V]
    Ac, Bc, Cc, Dc = compensator.A, compensator.B, compensator.C, compensator.D
    n, nc = Ad.shape[1], Ac.shape[0]
    A = np.zeros((len(speeds), n + nc, n + nc), dtype=complex)
    A[:, :n, :n] = Ad + Bu @ (Dc[:1, :2] @ Cy)
    A[:, :n, n:] = Bu @ Cc[:1]
    A[:, n:, :n] = Bc[:, :2] @ Cy
    A[:, n:, n:] = Ac
    # inputs (r, f, noise_x, noise_i): the noise enters where the measurement does
    B = np.zeros((len(speeds), n + nc, 4), dtype=complex)
    B[:, :n, :1] = Bu @ Dc[:1, 2:3]
    B[:, :n, 1:2] = Bf
    B[:, :n, 2:] = Bu @ Dc[:1, :2]
    B[:, n:, 0], B[:, n:, 2:] = Bc[:, 2], Bc[:, :2]
    k_mx, k_mi = rig.position_sensor_gain_v_per_m, rig.current_sensor_gain_v_per_a
    plant_rows = np.hstack([plant.C, np.zeros((4, nc))])
    innovation = np.hstack([Dc[1:2, :2] @ Cy, Cc[1:2]]).ravel()   # nu = D_nu (y, r) + C_nu z_c [V]
    C = np.vstack([plant_rows[0] / k_mx, plant_rows[1], plant_rows[2], plant_rows[3] / k_mi, innovation / k_mx])
    D = np.zeros((5, 4), dtype=complex)
    D[0, 2] = 1 / k_mx
    D[4, 0], D[4, 2:] = Dc[1, 2] / k_mx, Dc[1, :2] / k_mx
    return LoopAtSpeed(A, B, C, D, speeds, plant.n_modes)


@dataclass(frozen=True)
class SpeedSweep:
    """Closed-loop rotor modes over speed: ``poles_s`` [rad/s], ``whirl_hz`` and ``damping``
    of shape (speeds, modes, 2), [..., 0] backward and [..., 1] forward whirl (frequency
    [Hz] >= 0, damping ratio zeta = -Re s / |s|); ``spectral_radius`` max |z| per speed."""

    speeds_rpm: np.ndarray
    poles_s: np.ndarray
    spectral_radius: np.ndarray

    @property
    def whirl_hz(self) -> np.ndarray:
        return np.abs(self.poles_s.imag) / (2 * np.pi)

    @property
    def damping(self) -> np.ndarray:
        return -self.poles_s.real / np.maximum(np.abs(self.poles_s), 1e-12)

    @property
    def stable(self) -> np.ndarray:
        return self.spectral_radius < 1.0


def sweep(loop: LoopAtSpeed) -> SpeedSweep:
    """Each speed's rotor modes: the closed-loop eigenvalue of each mode's backward and forward
    whirl, picked by participation (``analysis.participation``: mode j's part is that of its
    states eta_j, eta'_j, independent of the states' units, so the controller's and filter's
    poles, in which the rotor takes no part, are never taken for a rotor mode)."""
    n = loop.n_modes
    poles = np.empty((len(loop.speeds_rpm), n, 2), dtype=complex)
    radius = np.empty(len(loop.speeds_rpm))
    for k, A in enumerate(loop.A):
        z, p = participation(A)
        s = z_to_s(z, RIG.sample_time_s)
        poles[k] = s[whirl_by_mode(s, p[:n] + p[n:2 * n])]
        radius[k] = np.max(np.abs(z))
    return SpeedSweep(loop.speeds_rpm, poles, radius)


def stable(loop: LoopAtSpeed) -> np.ndarray:
    """Per speed: every closed-loop pole inside the unit circle."""
    return np.max(np.abs(np.linalg.eigvals(loop.A)), axis=-1) < 1.0


def critical_speeds_rpm(speeds_rpm: np.ndarray, forward_hz: np.ndarray) -> list[float]:
    """Speeds [rpm] where a forward whirl meets the 1x line f = n / 60 (linear interpolation
    between the sweep's speeds): the unbalance's synchronous force excites that mode there."""
    gap = forward_hz - speeds_rpm / 60
    k = np.flatnonzero(np.sign(gap[:-1]) * np.sign(gap[1:]) < 0)
    return [float(speeds_rpm[i] - gap[i] * (speeds_rpm[i + 1] - speeds_rpm[i]) / (gap[i + 1] - gap[i])) for i in k]


def unbalance_states(loop: LoopAtSpeed, unbalance_kg_m: float) -> np.ndarray:
    """Steady response to the unbalance's forward synchronous force U Omega^2 e^{i Omega t} at the
    bearing plane, per speed: the loop's complex state amplitudes (speeds, states); the plant's
    modal coordinates eta_1..n come first.  Discrete steady state: Z = (e^{i Omega T} I - A)^-1 B_f F."""
    omega = rad_s(loop.speeds_rpm)
    force = unbalance_kg_m * omega**2
    z = np.exp(1j * omega * RIG.sample_time_s)
    n = loop.A.shape[1]
    return np.linalg.solve(z[:, None, None] * np.eye(n)[None] - loop.A,
                           loop.B[:, :, 1:2] * force[:, None, None])[:, :, 0]


def unbalance_response(loop: LoopAtSpeed, unbalance_kg_m: float) -> np.ndarray:
    """``unbalance_states`` as complex amplitudes (speeds, outputs) of ``LOOP_OUTPUTS``: an isotropic
    rotor whirls in a circle, so |amplitude| is the orbit's radius, and each plane's sinusoid's
    amplitude."""
    force = unbalance_kg_m * rad_s(loop.speeds_rpm) ** 2
    return unbalance_states(loop, unbalance_kg_m) @ loop.C.T + force[:, None] * loop.D[:, 1][None]


class RunUpSimulation:
    """Time simulation of the closed loop in both planes, the speed held or ramped (run-up).

    The speed follows n(t) = min(n_set, n_0 + a t) (a = 0: held at n_set); the loop is
    re-discretised every ``CHUNK`` samples at the chunk's mean speed (the gyroscopic matrix
    changes with speed), and stepped exactly in between.  Inputs: the unbalance's force
    U Omega^2 e^{i phi}, phi = integral of Omega dt, plus a random force at the bearing
    (complex: independent in both planes) and the sensors' noise; ``watched_row`` (over the plant's
    states) adds the x-z plane's deflection at one more point of the shaft.  The run stops when the
    rotor's orbit at the bearing reaches the touchdown bearing's clearance or either plane's
    coil current reaches the amplifier's limit (beyond it the linear model no longer holds).
    """

    columns = ("x_bearing_m", "y_bearing_m", "sensor_reading_m", "current_a", "innovation_m", "speed_rpm",
               "x_watched_m")
    CHUNK = 100                      # samples per re-discretisation (5 ms)

    def __init__(self, plant: SpinningPlant, compensator: Compensator, speed_rpm: float, run_up_rpm_per_s: float,
                 unbalance_kg_m: float, force_sigma_n: float, noise_sigma_v: tuple[float, float], seed: int = 0,
                 clearance_m: float = RIG.touchdown_m, current_limit_a: float = RIG.current_limit_a,
                 watched_row: np.ndarray | None = None, explain=lambda: ""):
        self.plant, self.compensator = plant, compensator
        self.sample_time_s = RIG.sample_time_s
        self.target_rpm, self.rate_rpm_per_s = float(speed_rpm), float(run_up_rpm_per_s)
        self.start_rpm = 0.0 if run_up_rpm_per_s > 0 else float(speed_rpm)
        self.unbalance_kg_m = unbalance_kg_m
        self.sigma = np.array([force_sigma_n, *noise_sigma_v])
        self.rng = np.random.default_rng(seed)
        self.clearance_m, self.current_limit_a = clearance_m, current_limit_a
        self.explain = explain
        self.state = np.zeros(closed_loop_at_speed(plant, compensator, [0.0]).A.shape[1], dtype=complex)
        # x at a watched point of the shaft [m] from the plant's states (e.g. where a mode moves most)
        self.watched_row = np.zeros(len(self.state)) if watched_row is None else \
            np.concatenate([watched_row, np.zeros(len(self.state) - len(watched_row))])
        self.step, self.phase_rad = 0, 0.0
        self.stop_reason = ""
        self.stopped_at_s: float | None = None
        self._loop_key: float | None = None

    def carry_on_from(self, other: RunUpSimulation) -> RunUpSimulation:
        """Continue ``other``'s run: time, spin angle, noise stream, speed reached and, if the loop
        has the same order, state (a run-up goes on from the speed it had reached)."""
        self.rng, self.step, self.phase_rad = other.rng, other.step, other.phase_rad
        self.stopped_at_s, self.stop_reason = other.stopped_at_s, other.stop_reason
        if self.rate_rpm_per_s > 0:
            self.start_rpm = min(other.speed_at(other.step), self.target_rpm) - self.rate_rpm_per_s * self.step * \
                self.sample_time_s
        if other.state.shape == self.state.shape:
            self.state[:] = other.state
        return self

    def speed_at(self, step) -> np.ndarray:
        """Speed [rpm] at sample ``step`` (scalar or array)."""
        ramp = self.start_rpm + self.rate_rpm_per_s * np.asarray(step) * self.sample_time_s
        return np.minimum(ramp, self.target_rpm) if self.rate_rpm_per_s > 0 else np.full(np.shape(step),
                                                                                          self.target_rpm)

    def _loop(self, speed_rpm: float) -> LoopAtSpeed:
        key = round(speed_rpm, 1)
        if key != self._loop_key:
            self._loop_key, self._cached = key, closed_loop_at_speed(self.plant, self.compensator, [key])
        return self._cached

    def advance(self, n_steps: int) -> np.ndarray:
        if self.stopped_at_s is not None or n_steps <= 0:
            return np.empty((0, 1 + len(self.columns)))
        rows = []
        done = 0
        while done < n_steps and self.stopped_at_s is None:
            count = min(self.CHUNK - self.step % self.CHUNK, n_steps - done)
            rows.append(self._chunk(count))
            done += count
        return np.vstack(rows)

    def _chunk(self, n_steps: int) -> np.ndarray:
        steps = self.step + np.arange(n_steps)
        speed = self.speed_at(steps)
        loop = self._loop(float(np.mean(speed)))
        omega = rad_s(speed)
        phase = self.phase_rad + np.cumsum(omega) * self.sample_time_s - omega * self.sample_time_s
        unbalance = self.unbalance_kg_m * omega**2 * np.exp(1j * phase)          # U Omega^2 e^{i phi} [N]
        noise = (self.rng.standard_normal((3, n_steps)) + 1j * self.rng.standard_normal((3, n_steps))) \
            * self.sigma[:, None]
        U = np.vstack([np.zeros(n_steps), unbalance + noise[0], noise[1], noise[2]])
        A, drive = loop.A[0], loop.B[0] @ U
        X = np.empty((A.shape[0], n_steps), dtype=complex)
        x = self.state
        for k in range(n_steps):
            X[:, k] = x
            x = A @ x + drive[:, k]
        Y = loop.C @ X + loop.D @ U
        r_b, current = Y[LOOP_OUTPUTS.index("r_bearing_m")], Y[LOOP_OUTPUTS.index("current_a")]
        touchdown = ~(np.abs(r_b) < self.clearance_m)
        saturated = ~(np.maximum(np.abs(current.real), np.abs(current.imag)) < self.current_limit_a)
        out = np.flatnonzero(touchdown | saturated)
        done = n_steps
        if out.size:
            done = int(out[0]) + 1
            self.stopped_at_s = (self.step + done) * self.sample_time_s
            self.stop_reason = (f"the rotor's orbit at the bearing reached the touchdown bearing's "
                                f"{self.clearance_m * 1e6:.0f} µm clearance at {speed[out[0]]:.0f} rpm"
                                if touchdown[out[0]] else
                                f"a coil current reached the amplifier's limit of {self.current_limit_a:.1f} A "
                                f"at {speed[out[0]]:.0f} rpm, where the linear model ends")
        else:
            self.state = x
        self.phase_rad = float(np.mod(phase[done - 1] + omega[done - 1] * self.sample_time_s, 2 * np.pi))
        t = (self.step + np.arange(done)) * self.sample_time_s
        self.step += done
        return np.column_stack([t, r_b[:done].real, r_b[:done].imag,
                                Y[LOOP_OUTPUTS.index("sensor_reading_m"), :done].real, current[:done].real,
                                Y[LOOP_OUTPUTS.index("innovation_m"), :done].real, speed[:done],
                                (self.watched_row @ X[:, :done]).real])

    def status_message(self) -> str:
        if self.stopped_at_s is None:
            return ""
        return f"Stopped at t = {self.stopped_at_s * 1e3:.1f} ms: {self.stop_reason}. {self.explain()}"
