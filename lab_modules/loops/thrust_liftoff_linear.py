"""The lift-off loop of ``thrust_liftoff_loop.run`` as a linear system: its poles, its noise at
steady state (discrete Lyapunov equation) and its open loop at the plant input (margins).

The loop is built by pushing unit vectors through one sample written like the compiled kernel
(``_linear_step``), on the linear plant (eq. 5), without saturation or stops, with the filter's
steady-state gain K∞; so the pole map and the noise analysis describe the loop that runs.  The
extended filter (``estimators.thrust_ekf``) has the same steady state at the centre as the Taylor
filter, so it shares this analysis.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import control
import numpy as np
import scipy.linalg

from lab_modules import analysis
from lab_modules.loops.thrust_liftoff_loop import ThrustSetup
from lab_modules.plants.thrust_bearing import discrete_current_loop


@dataclass(frozen=True)
class LinearLoop:
    """The loop of ``run`` on the linear plant, without saturation or stops, with the
    steady-state filter gain K∞:  s_{k+1} = M s_k + N n_k,  y_k = C s_k + D n_k,
    noise n = (sensor V [m], force f_dis [N]) per sample.

    State: plant (x, v), G(s) (2, if on), integral, previous error, derivative term,
    filter prediction (x̂, v̂) (if ``with_filter``).  Outputs: ``OUTPUTS``."""

    M: np.ndarray
    N: np.ndarray
    C: np.ndarray
    D: np.ndarray

    def poles(self) -> np.ndarray:
        """z-plane poles."""
        return np.linalg.eigvals(self.M)

    def stable(self) -> bool:
        return bool(np.max(np.abs(self.poles())) < 1.0)

    def output_std(self, sensor_noise_m: float, force_noise_n: float) -> dict[str, float]:
        """Steady-state standard deviation of each output for white noise of these
        standard deviations (discrete Lyapunov equation, scipy); inf when a mode the noise
        reaches is unstable."""
        per_sensor, per_force = self.unit_variances
        var = sensor_noise_m**2 * per_sensor + force_noise_n**2 * per_force
        return {name: float(np.sqrt(max(v, 0.0))) for name, v in zip(OUTPUTS, var)}

    @cached_property
    def unit_variances(self) -> tuple[np.ndarray, np.ndarray]:
        """Output variances for unit white sensor noise and unit white force (the two add)."""
        # the states span metres to amperes: balance M first (X = S X' S^T), or the solve is ill-conditioned
        M, (scale, _) = scipy.linalg.matrix_balance(self.M, permute=False, separate=True)
        out = []
        for j in range(self.N.shape[1]):
            n = self.N[:, j] / scale
            Q = excited_subspace(M, n)
            reached = Q.T @ M @ Q
            if Q.shape[1] and np.max(np.abs(np.linalg.eigvals(reached))) >= 1.0:
                out.append(np.full(self.C.shape[0], np.inf))
                continue
            X = scale[:, None] * (Q @ scipy.linalg.solve_discrete_lyapunov(reached, np.outer(Q.T @ n, Q.T @ n))
                                  @ Q.T) * scale[None, :]
            out.append(np.einsum("ij,jk,ik->i", self.C, X, self.C) + self.D[:, j] ** 2)
        return out[0], out[1]


def excited_subspace(M: np.ndarray, n: np.ndarray, tolerance: float = 1e-6) -> np.ndarray:
    """An orthonormal basis Q of the states the noise input ``n`` reaches: span(n, M n, M² n, ...)
    (Krylov, each new direction orthogonalised twice and kept if more than ``tolerance`` of it is
    new).  The steady-state covariance X = M X Mᵀ + n nᵀ lives there, X = Q X_q Qᵀ; a mode the noise
    does not reach, such as the integrator of a PID with Ki = 0 (a pole at z = 1), would make the
    Lyapunov equation on all states singular."""
    basis: list[np.ndarray] = []
    candidates = [n]
    while candidates and len(basis) < M.shape[0]:
        vector = candidates.pop()
        size = np.linalg.norm(vector)
        for _ in range(2):
            for q in basis:
                vector = vector - (q @ vector) * q
        if size > 0 and np.linalg.norm(vector) > tolerance * size:
            basis.append(vector / np.linalg.norm(vector))
            candidates.append(M @ basis[-1])
    return np.column_stack(basis) if basis else np.zeros((M.shape[0], 0))


#: Outputs of ``LinearLoop``: true x, measured z, corrected estimate x̂ [m], current command [A].
OUTPUTS = ("x_true_m", "x_measured_m", "x_estimated_m", "current_command_a")


def _linear_step(setup: ThrustSetup, with_g: bool, with_filter: bool):
    """(number of states, step): one sample of ``run`` on the linear plant, without saturation or
    stops, written like the kernel.  ``step(state, noise, injected=None)`` returns (next state,
    outputs ``OUTPUTS``); with ``injected`` the plant side (G(s), coil, filter prediction with the
    measured current) is driven by it instead of the PID's command: the loop broken at the plant input."""
    s, b = setup, setup.bearing
    T = b.sample_time_s
    Phi, _, Gamma = b.exact_discretisation()
    G_A, G_B, G_C, G_D = discrete_current_loop(T)
    Phi_f, B_f, _ = s.design.matrices
    K = s.design.steady_state[0]
    alpha = s.derivative_filter_s / (s.derivative_filter_s + T)
    o = 4 if with_g else 2                         # index of the integral
    n = o + 3 + (2 if with_filter else 0)

    def step(state, noise, injected=None):
        x = state[:2]
        g = state[2:4] if with_g else np.zeros(2)
        integral, previous, d_term = state[o], state[o + 1], state[o + 2]
        z = x[0] + noise[0]
        x_pred = state[o + 3:o + 5] if with_filter else np.zeros(2)
        x_corr = x_pred + K * (z - x_pred[0])
        e = -(x_corr[0] if s.use_estimate else z)
        raw_d = (-s.derivative_a_s_per_m * x_corr[1] if s.use_estimate and s.derivative_from_velocity
                 else s.derivative_a_s_per_m * (e - previous) / T)
        d_new = alpha * d_term + (1 - alpha) * raw_d
        command = s.proportional_a_per_m * e + integral + d_new
        drive = command if injected is None else injected
        i = G_C @ g + G_D * drive if with_g else drive
        out = np.empty(n)
        out[:2] = Phi @ x + Gamma * (b.current_stiffness_n_per_a * i + noise[1])
        if with_g:
            out[2:4] = G_A @ g + G_B * drive
        out[o], out[o + 1], out[o + 2] = integral + s.integral_a_per_m_s * T * e, e, d_new
        if with_filter:
            out[o + 3:o + 5] = Phi_f @ x_corr + B_f * i
        return out, np.array([x[0], z, x_corr[0], command])
    return n, step


def linear_loop(setup: ThrustSetup, current_loop: bool | None = None, with_filter: bool = True) -> LinearLoop:
    """``LinearLoop`` of ``setup`` (G(s) as set, or forced on/off by ``current_loop``).
    Built by pushing unit vectors through one step written like the kernel's, so the
    pole map and the noise analysis describe the loop that runs.  ``with_filter=False``
    drops the filter's states (only allowed for measured feedback, where the filter
    is outside the loop)."""
    with_g = setup.current_loop if current_loop is None else current_loop
    if not with_filter and setup.use_estimate:
        raise ValueError("the filter is inside the loop when the estimate is fed back")
    n, step = _linear_step(setup, with_g, with_filter)
    zero_state, zero_noise = np.zeros(n), np.zeros(2)
    by_state = [step(column, zero_noise) for column in np.eye(n)]
    by_noise = [step(zero_state, column) for column in np.eye(2)]
    return LinearLoop(M=np.column_stack([r[0] for r in by_state]), N=np.column_stack([r[0] for r in by_noise]),
                      C=np.column_stack([r[1] for r in by_state]), D=np.column_stack([r[1] for r in by_noise]))


def loop_at_plant_input(setup: ThrustSetup) -> control.StateSpace:
    """Open loop L broken at the current command i_c (S = 1 / (1 + L)): the linear loop of
    ``linear_loop`` with a signal injected where the plant side reads the command and the PID's
    command read back, sign included.  The filter's prediction uses the measured coil current,
    so the filter sits on both sides of the break only through its states."""
    n, step = _linear_step(setup, setup.current_loop, True)

    def broken(state, injected):
        state_next, outputs = step(state, np.zeros(2), injected[0])
        return state_next, outputs[3:]            # the current command
    return -analysis.state_space_from_step(broken, n, 1, setup.bearing.sample_time_s)
