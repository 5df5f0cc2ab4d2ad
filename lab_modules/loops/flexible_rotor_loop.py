"""The flexible rotor's bearing axis in closed loop (paper 000, §I, Fig. 2).

The rotor model (``plants.flexible_rotor``) with its sensor anywhere along the
shaft, closed by the paper's PID on the measured position or on the rigid-model
Kalman filter's estimate (python-control interconnections), and its time
simulation by exact discrete state-space stepping.
"""

from __future__ import annotations

import control
import numpy as np

from lab_modules.plants.flexible_rotor import FlexibleRotor, modal_plant
from lab_modules.plants.radial_bearing import RIG, BearingAxis

#: Inputs and outputs of the loop returned by ``closed_loop``.
LOOP_INPUTS = ("reference_m", "disturbance_n", "noise_position_v", "noise_current_v")
LOOP_OUTPUTS = ("sensor_reading_m", "x_bearing_m", "x_sensor_m", "current_a")


def discrete_plant(rotor: FlexibleRotor, sensor_z_m: float, n_modes: int, sensor_lag_s: float,
                   rig: BearingAxis = RIG) -> control.StateSpace:
    """``modal_plant`` discretised with a zero-order hold at T = 50 µs (the DSP's sampling)."""
    return control.c2d(modal_plant(rotor, sensor_z_m, n_modes, sensor_lag_s, rig), rig.sample_time_s, "zoh")


def pid_compensator(controller: control.StateSpace, rig: BearingAxis = RIG) -> control.StateSpace:
    """The PID acting on the measured position: u = C(z) (K_mx r - y_position).

    Inputs (y_position [V], y_current [V], r [m]); output i_ref [V].
    """
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(M)) for M in
                      (controller.A, controller.B, controller.C, controller.D))
    error = np.array([[-1.0, 0.0, rig.position_sensor_gain_v_per_m]])   # e from the inputs
    return control.ss(Ac, Bc @ error, Cc, Dc @ error, controller.dt)


def kalman_compensator(controller: control.StateSpace, model: control.StateSpace,
                       kalman_gain: np.ndarray, rig: BearingAxis = RIG) -> control.StateSpace:
    """The PID acting on the Kalman filter's estimate (paper 000 eq. 2, §II, Fig. 3).

    The filter's model is the paper's *rigid* one-axis model (eq. 3-4, 12:
    states x, v, i, x_d, equivalent mass 21.5 kg); it knows nothing of the
    bending modes.  With the steady-state correction gain K and the
    prediction x_p:

        x_hat = (I - K C) x_p + K y                       (correction, eq. 2)
        e     = K_mx (r - x_hat[0])                       (undelayed estimate fed back)
        u     = C_c x_c + D_c e,    x_c+ = A_c x_c + B_c e  (PID)
        x_p+  = A x_hat + B u                             (prediction, eq. 2)

    Inputs (y_position [V], y_current [V], r [m]); output i_ref [V];
    states (x_p, x_c).
    """
    A, B, C = (np.asarray(M) for M in (model.A, model.B, model.C))
    Bu = B[:, :1]
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(M)) for M in
                      (controller.A, controller.B, controller.C, controller.D))
    K = np.asarray(kalman_gain)
    n = A.shape[0]
    h = np.zeros((1, n))
    h[0, 0] = rig.position_sensor_gain_v_per_m
    correction = np.eye(n) - K @ C
    # e = Ep x_p + Ey (y, r)
    Ep = -h @ correction
    Ey = np.hstack([-h @ K, [[rig.position_sensor_gain_v_per_m]]])
    Acomp = np.block([[A @ correction + Bu @ Dc @ Ep, Bu @ Cc],
                      [Bc @ Ep, Ac]])
    Bcomp = np.vstack([np.hstack([A @ K, np.zeros((n, 1))]) + Bu @ Dc @ Ey, Bc @ Ey])
    Ccomp = np.hstack([Dc @ Ep, Cc])
    return control.ss(Acomp, Bcomp, Ccomp, Dc @ Ey, controller.dt)


def closed_loop(plant: control.StateSpace, compensator: control.StateSpace,
                rig: BearingAxis = RIG) -> control.StateSpace:
    """Plant and compensator closed by ``control.feedback`` (positive sign: the
    compensator already subtracts the measurement).

    The plant is extended so that the reference and the sensors' noise enter
    as inputs: the compensator sees (y_position + noise, y_current + noise, r).
    Inputs ``LOOP_INPUTS``; outputs ``LOOP_OUTPUTS`` (the sensor's noisy reading
    and the rotor at the bearing and at the sensor in metres, the true coil current).
    """
    A, B, C = (np.asarray(M) for M in (plant.A, plant.B, plant.C))
    n = A.shape[0]
    k_mx, k_mi = rig.position_sensor_gain_v_per_m, rig.current_sensor_gain_v_per_a
    # inputs (i_ref, f_z, r, noise_x, noise_i); outputs (y_pos + noise_x, y_cur + noise_i, r, x_b, x_s, K_mi i)
    B_ext = np.hstack([B, np.zeros((n, 3))])
    C_ext = np.vstack([C[0], C[3], np.zeros(n), C[1], C[2], C[3]])
    D_ext = np.zeros((6, 5))
    D_ext[0, 3] = D_ext[1, 4] = D_ext[2, 2] = 1.0
    extended = control.ss(A, B_ext, C_ext, D_ext, plant.dt)
    # the compensator reads (y_pos, y_cur, r) and drives i_ref only
    nc = compensator.nstates
    Cf, Df = np.zeros((5, nc)), np.zeros((5, 6))
    Cf[0], Df[0, :3] = np.asarray(compensator.C)[0], np.asarray(compensator.D)[0]
    feedback_path = control.ss(compensator.A, np.hstack([compensator.B, np.zeros((nc, 3))]), Cf, Df, plant.dt)
    loop = control.feedback(extended, feedback_path, sign=1)
    # outputs in physical units: reading [m], x_b [m], x_s [m], true coil current i [A]
    scale = np.zeros((4, 6))
    scale[0, 0], scale[1, 3], scale[2, 4], scale[3, 5] = 1 / k_mx, 1.0, 1.0, 1 / k_mi
    inputs = np.zeros((5, 4))
    inputs[2, 0], inputs[1, 1], inputs[3, 2], inputs[4, 3] = 1.0, 1.0, 1.0, 1.0
    return control.ss(loop.A, loop.B @ inputs, scale @ loop.C, scale @ loop.D @ inputs, plant.dt,
                      inputs=list(LOOP_INPUTS), outputs=list(LOOP_OUTPUTS))


class LoopSimulation:
    """Time simulation of a closed loop from ``closed_loop``: exact discrete
    state-space stepping (numpy, the whole chunk's inputs at once).

    ``inputs(step, n)`` returns the deterministic inputs (reference [m],
    disturbance [N]) for the next n samples; random inputs are the force
    noise ``force_sigma_n`` and the sensors' noise (sigmas in V).  The run
    stops when the rotor at the bearing leaves the air gap or the coil current
    exceeds the amplifier's limit (beyond it the linear model no longer holds).
    """

    columns = LOOP_OUTPUTS + ("reference_m",)

    def __init__(self, loop: control.StateSpace, inputs, force_sigma_n: float, noise_sigma_v: tuple[float, float],
                 seed: int = 0, touchdown_m: float = RIG.touchdown_m,
                 current_limit_a: float = RIG.current_limit_a, explain=lambda: ""):
        self.loop = loop
        self.sample_time_s = float(loop.dt)
        self.A, self.B, self.C, self.D = (np.asarray(M, dtype=float) for M in (loop.A, loop.B, loop.C, loop.D))
        self.state = np.zeros(self.A.shape[0])
        self.inputs = inputs
        self.sigma = np.array([force_sigma_n, *noise_sigma_v])
        self.rng = np.random.default_rng(seed)
        self.touchdown_m = touchdown_m
        self.current_limit_a = current_limit_a
        self.explain = explain
        self.stop_reason = ""
        self.step = 0
        self.stopped_at_s: float | None = None

    def carry_on_from(self, other: LoopSimulation) -> LoopSimulation:
        """Continue ``other``'s run (time, noise stream and, if the loop has the same order, state)."""
        self.rng, self.step = other.rng, other.step
        self.stopped_at_s, self.stop_reason = other.stopped_at_s, other.stop_reason
        if other.state.shape == self.state.shape:
            self.state[:] = other.state
        return self

    def advance(self, n_steps: int) -> np.ndarray:
        if self.stopped_at_s is not None or n_steps <= 0:
            return np.empty((0, 1 + len(self.columns)))
        reference, disturbance = self.inputs(self.step, n_steps)
        noise = self.rng.standard_normal((3, n_steps)) * self.sigma[:, None]
        U = np.vstack([reference, disturbance + noise[0], noise[1], noise[2]])
        drive = self.B @ U
        X = np.empty((self.A.shape[0], n_steps))
        x = self.state
        for k in range(n_steps):
            X[:, k] = x
            x = self.A @ x + drive[:, k]
        Y = self.C @ X + self.D @ U
        done = n_steps
        touchdown = ~(np.abs(Y[LOOP_OUTPUTS.index("x_bearing_m")]) < self.touchdown_m)
        saturated = ~(np.abs(Y[LOOP_OUTPUTS.index("current_a")]) < self.current_limit_a)
        out = np.flatnonzero(touchdown | saturated)
        if out.size:
            done = int(out[0]) + 1
            self.stopped_at_s = (self.step + done) * self.sample_time_s
            self.stop_reason = (f"the rotor left the {self.touchdown_m * 1e6:.0f} µm air gap at the bearing"
                                if touchdown[out[0]] else
                                f"the coil current reached the amplifier's limit of {self.current_limit_a:.1f} A "
                                "(rated force), where the linear model ends")
        else:
            self.state = x
        t = (self.step + np.arange(done)) * self.sample_time_s
        self.step += done
        return np.column_stack([t, Y[:, :done].T, reference[:done]])

    def status_message(self) -> str:
        if self.stopped_at_s is None:
            return ""
        return f"Stopped at t = {self.stopped_at_s * 1e3:.1f} ms: {self.stop_reason}. {self.explain()}"
