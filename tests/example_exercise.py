"""The smallest complete exercise: a mass on a spring and damper, pushed by a known force and
shaken by a random one, its position measured with noise, a linear Kalman filter (paper 000,
eq. 2; ``estimators.kalman``) estimating position and velocity.  Registered only in the tests,
which run the whole exercise contract over it: what every exercise must have, and no more.

Model (continuous, SI):  m ẍ + c ẋ + k x = F + w,  y = x + η;  held over each sample T (ZOH).
"""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np
import scipy.linalg

from lab_modules import analysis
from lab_modules.claims import Claim
from lab_modules.estimators.kalman import KalmanFilter
from lab_modules.exercises import Analysis, Chart, Exercise, PoleCategory, Series, registry
from lab_modules.parameters import Parameter, in_si

T = 1e-3                                        # sample time [s]
P = Parameter
PARAMETERS = (
    P("mass_kg", "Mass m", "kg", 1.0, 0.1, 10.0, "The moving mass.", step=0.1, group="Plant"),
    P("stiffness_n_per_m", "Spring k", "N/m", 100.0, 10.0, 1000.0, "Spring stiffness.", step=10.0, group="Plant"),
    P("damping_n_s_per_m", "Damper c", "N·s/m", 2.0, 0.0, 50.0, "Viscous damping.", step=0.5, group="Plant"),
    P("force_amplitude_n", "Force amplitude", "N", 1.0, 0.0, 10.0,
      "Known square-wave force F (period 2 s), the filter's input.", step=0.1, group="Input"),
    P("force_noise_n", "Random force σ_w", "N", 0.5, 0.01, 5.0,
      "Standard deviation of the random force w, held over each sample.", log=True, group="Noise"),
    P("sensor_noise_mm", "Sensor noise σ_η", "mm", 1.0, 0.01, 10.0,
      "Standard deviation of the position measurement's noise η.", log=True, group="Noise"),
    P("seed", "Noise seed", "", 0, 0, 10_000, "Seed of the random force and sensor noise.", integer=True),
)


def discrete_model(values: dict) -> tuple:
    """Discrete model (A, B force column, C, Q, R) of the spring (ZOH over T); Q = σ_w² B Bᵀ [m², m²/s²]."""
    m, k, c = values["mass_kg"], values["stiffness_n_per_m"], values["damping_n_s_per_m"]
    plant = control.c2d(control.ss([[0, 1], [-k / m, -c / m]], [[0], [1 / m]], [[1, 0]], 0), T)
    A, B, C = np.asarray(plant.A), np.asarray(plant.B), np.asarray(plant.C)
    return A, B, C, values["force_noise_n"] ** 2 * B @ B.T, np.array([[in_si(PARAMETERS, values)["sensor_noise_mm"] ** 2]])


class SpringSimulation:
    """The spring and its filter, one row per sample: the filter corrects with y_k, then predicts."""

    columns = ("x_true_m", "x_measured_m", "x_estimated_m", "x_sigma_m", "force_n", "nees")

    def __init__(self, values: dict):
        self.sample_time_s, self.values, self.step = T, values, 0
        self.A, self.B, C, Q, R = discrete_model(values)
        P0 = scipy.linalg.solve_discrete_lyapunov(self.A, Q)     # the mass already shaken at t = 0
        self.rng = np.random.default_rng(int(values["seed"]))
        self.state = self.rng.multivariate_normal(np.zeros(2), P0)
        self.filter = KalmanFilter(self.A, self.B, C, Q, np.diag(R), np.zeros(2), P0)

    def advance(self, n_steps: int) -> np.ndarray:
        rows = np.empty((n_steps, 1 + len(self.columns)))
        sigma_w, sigma_eta = self.values["force_noise_n"], in_si(PARAMETERS, self.values)["sensor_noise_mm"]
        for row in rows:
            t = self.step * T
            force = self.values["force_amplitude_n"] * np.sign(np.sin(np.pi * t))     # F(t), period 2 s
            y = self.state[0] + sigma_eta * self.rng.standard_normal()                  # y = x + η
            self.filter.update([y])
            error = self.state - self.filter.x
            nees = error @ np.linalg.solve(self.filter.covariance, error)               # eᵀ P⁻¹ e ~ χ²₂
            row[:] = (t, self.state[0], y, self.filter.x[0], np.sqrt(self.filter.covariance[0, 0]), force, nees)
            self.state = self.A @ self.state + self.B[:, 0] * (force + sigma_w * self.rng.standard_normal())
            self.filter.predict(force)
            self.step += 1
        return rows

    def status_message(self) -> str:
        return ""


SOURCE = "example (no paper): lab target"
CLAIMS = (
    Claim(SOURCE, "running filter's gain against scipy's DARE gain", "equal", "gain_relative_error",
          (None, 1e-6), "", note="|K − K_DARE| / |K_DARE| after the run"),
    Claim(SOURCE, "mean NEES of (x, v)", "2 (χ² with 2 degrees of freedom)", "mean_nees", (1.72, 2.31), "",
          note="99.7 % band of χ²(800) / 400: the error is correlated over tens of ms, so the 20 s run "
               "holds about 400 independent samples (metric nees_independent_samples)"),
    Claim(SOURCE, "RMS position estimate error against the sensor noise", "below 1", "error_over_noise",
          (None, 0.25), "", note="RMS(x̂ − x) / σ_η; the steady-state filter predicts 0.16"),
)


class SpringExample(Exercise):
    name = "spring_example"
    title = "Example: a mass on a spring with a Kalman filter"
    worksheet = str(Path(__file__).with_name("example_worksheet.md"))   # absolute: read from tests/
    parameters = PARAMETERS
    claims = CLAIMS
    default_duration_s = 20.0
    no_feedback_loop = "The force is a known open-loop input; the filter only watches."
    charts = (Chart("Position", "mm", (Series("measured", "x_measured_m", 1e3, "#b0b0b0"),
                                       Series("true", "x_true_m", 1e3, "#1f77b4"),
                                       Series("estimate", "x_estimated_m", 1e3, "#d62728")),
                    band=("x_estimated_m", "x_sigma_m")),
              Chart("Known force", "N", (Series("F", "force_n", 1.0, "#2ca02c"),)))

    def model(self, values: dict) -> dict:
        A, B, C, Q, R = discrete_model(values)
        return {"states": ["x [m]", "v [m/s]"], "sample_time_s": T,
                **{name: M.tolist() for name, M in zip("ABCQR", (A, B, C, Q, R))}}

    def analyse(self, values: dict) -> Analysis:
        A, B, C, Q, R = discrete_model(values)
        K, P_prior = analysis.steady_state_kalman(control.ss(A, B, C, 0, T), Q, R)
        P_post = P_prior - K @ C @ P_prior                                  # P⁺ = (I − K C) P⁻
        readouts = [("Natural frequency", np.sqrt(values["stiffness_n_per_m"] / values["mass_kg"]) / 2 / np.pi, "Hz"),
                    ("Steady-state gain K_x", K[0, 0], ""), ("Steady-state gain K_v", K[1, 0], "1/s"),
                    ("Position σ after correction", np.sqrt(P_post[0, 0]) * 1e3, "mm")]
        poles = {"open-loop plant": analysis.z_to_s(np.linalg.eigvals(A), T),
                 "filter error": analysis.z_to_s(np.linalg.eigvals(A - A @ K @ C), T)}   # e⁺ ← (I − K C) A e⁺
        return Analysis(readouts, poles)

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        return {"open-loop plant": PoleCategory.PLANT, "filter error": PoleCategory.FILTER_ERROR}

    def simulation(self, values: dict) -> SpringSimulation:
        return SpringSimulation(values)

    def metrics(self, values: dict, duration_s: float) -> dict:
        simulation = SpringSimulation(values)
        trace = simulation.advance(round(duration_s / T))
        x_true, x_estimated, nees = trace[:, 1], trace[:, 3], trace[:, 6]
        A, _, C, Q, R = discrete_model(values)
        P_prior = scipy.linalg.solve_discrete_are(A.T, C.T, Q, R)                # scipy's Riccati solution
        K_dare = (P_prior @ C.T @ np.linalg.inv(C @ P_prior @ C.T + R))[:, 0]    # K = P Cᵀ (C P Cᵀ + R)⁻¹
        return {"gain_relative_error": float(np.linalg.norm(simulation.filter.gain[0, :2] - K_dare)
                                             / np.linalg.norm(K_dare)),
                "mean_nees": float(np.mean(nees)),
                "nees_independent_samples": analysis.independent_samples((x_estimated - x_true) / trace[:, 4]),
                "error_over_noise": float(np.sqrt(np.mean((x_estimated - x_true) ** 2))
                                          / in_si(PARAMETERS, values)["sensor_noise_mm"])}


EXERCISE = SpringExample()


def contract_exercises() -> dict[str, Exercise]:
    """The registered exercises and this example, by name: the contract tests run over all of them."""
    return {**registry(), EXERCISE.name: EXERCISE}
