"""The ball of paper 001 levitated on its own self-sensing estimate: the position loop
closed on ŝ instead of a sensor (the question the paper's sensorless bearing leads to).

Once per PWM period T the controller reads the gap ŝ that eq. 18 and eq. 2 gave for the
period just ended (one period old, and an average over that period), and a PID sets the
mean coil current of the next period,

    i* = i_eq(r) + K_p e + K_i T Σe + D,   e = ŝ − r,
    D ← (τ D + K_d (e − e_prev)) / (τ + T),   τ = 1 / (n_f ω_c)            (filtered derivative)

with the gains placing the delay-free linearised loop's poles at −ω_c (a triple pole):
f_i K_d = 3 m ω_c, f_i K_p − k_s = 3 m ω_c², f_i K_i = m ω_c³, where f_i = i_eq |∂L/∂s| [N/A]
and k_s = ½ i_eq² ∂²L/∂s² [N/m] (the force law f = ½ i² |∂L/∂s|; the ball is unstable
with the pole √(k_s/m)).  The duty follows from i* with the dead-beat rule of the prescribed
loop, but sensorless: the current at the period's start is the measured one and the
inductance the estimate L̄ of the period before.  The ball is integrated with the coil
per sample (m s̈ = m g − ½ i² |∂L/∂s(s)|, semi-implicit Euler; the flux step with L at the
sample's start).

``linear_loop`` is the analysis: the plant linearised at the reference, discretised with
the period's mean current held over the period, the measurement the mean gap over the
period (the averaging) and one period of delay; from it the margins at the plant input,
the stable range of ω_c, the true-position spread that σ(ŝ) causes, the duty's spread (the
loop is linear only while the duty stays clear of its limits) and the statistical error of a
spread measured over a finite run.
"""

from __future__ import annotations

from typing import NamedTuple

import control
import numpy as np
import scipy.linalg
import scipy.optimize
from numba import njit

from lab_modules.loops.self_sensing_loop import (
    COLUMNS,
    TRAJECTORIES,
    SelfSensingLoop,
    SelfSensingSetup,
    duty_for_mean_current,
    estimate_period,
    fill_normal,
    gap_at,
    store_raw,
)
from lab_modules.plants.self_sensing_ball import GRAVITY, inductance, inductance_slope

CURVATURE_STEP_M = 1e-7          # central difference of ∂L/∂s for ∂²L/∂s²
DUTY_SLOPE_STEP_A = 1e-3         # central difference of the duty rule's slopes [A]
AUTOCORRELATION_FLOOR = 1e-9     # the closed loop's autocorrelation counts until its envelope falls below this
#: The loop state carried between runs, in ``run_levitated``'s order (SI units).
STATE = ("flux_wb", "gap_m", "velocity_m_s", "integral_a", "derivative_a", "previous_error_m",
         "inductance_estimate_h", "gap_estimate_m", "current_measured_a")
BANDWIDTH_SEARCH_RAD_S = (1.0, 2000.0)   # where the stable range of ω_c is looked for


class LevitationControl(NamedTuple):
    """The position loop on ŝ as ``run_levitated`` takes it (SI units)."""

    bandwidth_rad_s: float           # ω_c: the delay-free loop's triple pole at −ω_c [rad/s]
    derivative_filter_ratio: float   # n_f: the derivative filter's corner n_f ω_c [-]
    stop_deviation_m: float          # the run stops when |s − r| exceeds this [m]
    shortest_phase: float            # each phase keeps at least this share of the period [-]


@njit(cache=True, nogil=True)
def linearisation(gap_m, constants, mass_kg):
    """(i_eq [A], f_i [N/A], k_s [N/m]) of the force law f = ½ i² |∂L/∂s| at a gap [m]."""
    slope = abs(inductance_slope(gap_m, constants))                   # |∂L/∂s| [H/m]
    curvature = (inductance_slope(gap_m + CURVATURE_STEP_M, constants)
                 - inductance_slope(gap_m - CURVATURE_STEP_M, constants)) / (2.0 * CURVATURE_STEP_M)
    current = np.sqrt(2.0 * mass_kg * GRAVITY / slope)                # ½ i² |∂L/∂s| = m g
    return current, current * slope, 0.5 * current**2 * curvature     # k_s = ½ i² ∂²L/∂s²


@njit(cache=True, nogil=True)
def levitation_gains(gap_m, constants, mass_kg, bandwidth_rad_s):
    """(K_p [A/m], K_i [A/(m·s)], K_d [A·s/m], i_eq [A]) of the triple-pole design at a gap [m]."""
    current, force_per_current, negative_stiffness = linearisation(gap_m, constants, mass_kg)
    kd = 3.0 * mass_kg * bandwidth_rad_s / force_per_current
    kp = (negative_stiffness + 3.0 * mass_kg * bandwidth_rad_s**2) / force_per_current
    ki = mass_kg * bandwidth_rad_s**3 / force_per_current
    return kp, ki, kd, current


@njit(cache=True, nogil=True)
def shortest_phase_samples(samples_per_period, trim_samples, shortest_phase):
    """The fewest samples either phase keeps [-]: the share ``shortest_phase`` of the period, and
    never fewer than a trimmed window needs; the duty stays inside [this, n − this] / n."""
    return max(2 * trim_samples + 3, int(shortest_phase * samples_per_period))


@njit(cache=True, nogil=True)
def run_levitated(first_period, n_periods, state, constants, setup, control, rng_state, out, raw):
    """Simulate up to ``n_periods`` PWM periods of the ball levitated on ŝ; returns the number
    run (fewer when the ball leaves its reference by more than ``control.stop_deviation_m``).

    state: ``STATE`` values, in place.  constants: ``SelfSensingBall.constants``.  setup:
    ``PwmRun`` (its gaps and trajectory give the reference).  control: ``LevitationControl``.
    rng_state, out, raw: as ``self_sensing_loop.run_periods``."""
    n = setup.samples_per_period
    ts = setup.sample_time_s
    v_bat = setup.battery_voltage_v
    r = setup.resistance_ohm
    inv_mu = 1.0 / setup.current_gain
    inv_eta = 1.0 / setup.voltage_gain
    di = setup.current_offset_a
    dv = setup.voltage_offset_v
    sig_i = setup.sigma_current_a
    sig_v = setup.sigma_voltage_v
    trim = setup.trim_samples
    gap_1 = setup.gap_1_m
    gap_2 = setup.gap_2_m
    transition = setup.transition_s
    mode = setup.trajectory
    mass = setup.ball_mass_kg
    hold = setup.hold_s
    bandwidth = control.bandwidth_rad_s
    tau = 1.0 / (control.derivative_filter_ratio * bandwidth)
    stop = control.stop_deviation_m
    period_s = n * ts
    flux, gap, velocity, integral, derivative, previous_error, l_hat, s_hat, i_measured = (
        state[0], state[1], state[2], state[3], state[4], state[5], state[6], state[7], state[8])
    current_m = np.empty(n + 1)
    voltage_m = np.empty(n + 1)
    fit_1 = np.empty(7)
    fit_2 = np.empty(7)
    noise = np.empty(2 * n + 2)
    true_i = np.empty(n)
    min_on = shortest_phase_samples(n, trim, control.shortest_phase)
    done = n_periods
    for p in range(n_periods):
        t0 = (first_period + p) * period_s
        reference = gap_at(t0 + 0.5 * period_s, gap_1, gap_2, hold, transition, mode)
        kp, ki, kd, i_ref = levitation_gains(reference, constants, mass, bandwidth)
        error = s_hat - reference                                          # e = ŝ − r [m]
        derivative = (tau * derivative + kd * (error - previous_error)) / (tau + period_s)
        integral += ki * period_s * error
        command = max(i_ref + kp * error + integral + derivative, 0.0)    # i* [A]
        previous_error = error
        chi = duty_for_mean_current(i_measured, l_hat, command, l_hat, r, v_bat, period_s)
        n_on = max(min_on, min(n - min_on, int(np.rint(chi * n))))
        if sig_i > 0.0 or sig_v > 0.0:
            fill_normal(rng_state, noise)
        else:
            noise[:] = 0.0
        l_sum = 0.0
        l_1_sum = 0.0
        l_2_sum = 0.0
        gap_sum = 0.0
        for k in range(n + 1):
            lk = inductance(gap, constants)
            current = flux / lk
            v = v_bat if k < n_on else -v_bat
            current_m[k] = current * inv_mu - di + sig_i * noise[2 * k]
            voltage_m[k] = v * inv_eta - dv + sig_v * noise[2 * k + 1]
            if k == n:
                break
            true_i[k] = current
            l_sum += lk
            gap_sum += gap
            if trim <= k <= n_on - trim:
                l_1_sum += lk
            elif n_on + trim <= k <= n - trim:
                l_2_sum += lk
            force = 0.5 * current * current * abs(inductance_slope(gap, constants))   # f = ½ i² |∂L/∂s| [N]
            a = r * ts / lk
            step = ts * (1.0 - a * (0.5 - a * (1.0 / 6.0 - a / 24.0)))      # (1 − e^(−a)) L / R, frozen L
            flux = flux * (1.0 - a * step / ts) + v * step
            velocity += (GRAVITY - force / mass) * ts                       # m s̈ = m g − f
            gap += velocity * ts
        store_raw(raw, p, t0, ts, true_i, current_m, voltage_m, n_on, v_bat)
        row = out[p]
        estimate_period(current_m, voltage_m, n_on, setup, constants, fit_1, fit_2, row)
        row[0] = gap_sum / n
        row[1] = l_sum / n
        row[19] = np.mean(true_i)
        row[20] = l_1_sum / (n_on - 2 * trim + 1)
        row[21] = l_2_sum / (n - n_on - 2 * trim + 1)
        row[22] = reference
        row[23] = s_hat                 # the estimate this period's current was set from
        row[24] = command
        row[25] = velocity
        l_hat, s_hat, i_measured = row[5], row[11], current_m[n]
        if not (np.isfinite(s_hat) and l_hat > 0.0 and abs(gap - reference) <= stop and gap > 0.0):
            done = p + 1
            break
    state[0], state[1], state[2], state[3], state[4], state[5], state[6], state[7], state[8] = (
        flux, gap, velocity, integral, derivative, previous_error, l_hat, s_hat, i_measured)
    return done


class LinearLoop(NamedTuple):
    """The position loop on ŝ linearised at a gap, one step per PWM period.  State
    (s [m], ṡ [m/s], ŝ of the period before [m], integral [A], derivative [A], e_prev [m],
    i* of the period before [A])."""

    open_loop: control.StateSpace     # L at the plant input (the current command), S = 1/(1 + L)
    closed: np.ndarray                # the closed loop's state matrix
    noise_input: np.ndarray           # where σ(ŝ) enters: the delayed estimate (unit column)
    period_s: float                   # T_pwm: one step of the loop [s]
    duty: float                       # χ_eq: the duty at the equilibrium [-]
    duty_row: np.ndarray              # δχ = duty_row · state: the duty rule linearised [1 per state unit]


def linear_loop(setup: SelfSensingSetup, control_: LevitationControl, gap_m: float) -> LinearLoop:
    """The loop of ``run_levitated`` linearised at ``gap_m``.  The duty rule sets each period's
    end current; a change of the command moves the switching instant χT, so the current keeps
    the last command's level until χT and has the new one after it (χ = ½(1 + R i_eq/v_bat), the
    equilibrium duty).  The measurement is the mean gap over the period (eq. 18 averages the
    period), read by the controller one period later."""
    rig = setup.rig
    m = rig.ball_mass_kg
    constants = rig.constants()
    kp, ki, kd, current = levitation_gains(gap_m, constants, m, control_.bandwidth_rad_s)
    _, force_per_current, negative_stiffness = linearisation(gap_m, constants, m)
    period = setup.period_s
    v_bat = setup.battery_voltage_v or rig.battery_voltage_v
    duty = 0.5 * (1.0 + rig.coil_resistance_ohm * current / v_bat)
    # (s, ṡ, q = ∫s) under a held current: ṡ = v, v̇ = (k_s s − f_i i)/m, q̇ = s
    block = np.zeros((4, 4))
    block[0, 1], block[1, 0], block[1, 3], block[2, 0] = 1.0, negative_stiffness / m, -force_per_current / m, 1.0
    first, second = (scipy.linalg.expm(block * span) for span in (duty * period, (1.0 - duty) * period))
    phi = second[:3, :3] @ first[:3, :3]
    from_previous = second[:3, :3] @ first[:3, 3]              # the last command's current until χT
    from_command = second[:3, 3]                                # the new command's after it
    tau = 1.0 / (control_.derivative_filter_ratio * control_.bandwidth_rad_s)
    hold, gain = tau / (tau + period), kd / (tau + period)
    u_row = np.array([0.0, 0.0, kp + ki * period + gain, 1.0, hold, -gain, 0.0])   # i*ₚ from the state
    plant = np.zeros((7, 7))
    plant[:2, :2] = phi[:2, :2]
    plant[:2, 6] = from_previous[:2]
    plant[2, :2] = phi[2, :2] / period                          # ŝ = (1/T)∫ s dt over the period
    plant[2, 6] = from_previous[2] / period
    plant[3] = [0.0, 0.0, ki * period, 1.0, 0.0, 0.0, 0.0]
    plant[4] = [0.0, 0.0, gain, 0.0, hold, -gain, 0.0]
    plant[5, 2] = 1.0
    u_column = np.array([from_command[0], from_command[1], from_command[2] / period, 0.0, 0.0, 0.0, 1.0])
    open_loop = control.ss(plant, u_column[:, None], -u_row[None, :], 0.0, period)   # L = −(i* per i*)
    noise = np.zeros(7)
    noise[2] = 1.0
    # δχ = ∂χ/∂i* δi*ₚ + ∂χ/∂i₀ δi*ₚ₋₁: the duty rule's slopes (central differences, exact for its
    # quadratic dependence), the period starting at the last command's level
    inductance_h = float(rig.inductance_h(gap_m))
    def duty_at(start_a: float, target_a: float) -> float:
        return duty_for_mean_current(start_a, inductance_h, target_a, inductance_h, rig.coil_resistance_ohm, v_bat,
                                     period)
    step = DUTY_SLOPE_STEP_A
    per_command = (duty_at(current, current + step) - duty_at(current, current - step)) / (2 * step)
    per_start = (duty_at(current + step, current) - duty_at(current - step, current)) / (2 * step)
    duty_row = per_command * u_row + per_start * np.eye(7)[6]
    return LinearLoop(open_loop, plant + np.outer(u_column, u_row), noise, period, duty, duty_row)


def spectral_radius(loop: LinearLoop) -> float:
    """Largest |eigenvalue| of the closed loop (stable below 1)."""
    return float(np.max(np.abs(np.linalg.eigvals(loop.closed))))


def stationary_covariance(loop: LinearLoop, sigma_estimate_m: float) -> np.ndarray | None:
    """The closed loop's state covariance when the fed-back ŝ carries white noise σ(ŝ) [m] per
    period, X = A X Aᵀ + σ² g gᵀ (the discrete Lyapunov equation); None for an unstable loop."""
    if spectral_radius(loop) >= 1.0:
        return None
    return scipy.linalg.solve_discrete_lyapunov(loop.closed, sigma_estimate_m**2 * np.outer(loop.noise_input,
                                                                                         loop.noise_input))


def predicted_gap_spread_m(loop: LinearLoop, sigma_estimate_m: float) -> float:
    """Std of the true gap [m], √X₀₀ of ``stationary_covariance``; NaN for an unstable loop."""
    x = stationary_covariance(loop, sigma_estimate_m)
    return float("nan") if x is None else float(np.sqrt(x[0, 0]))


def predicted_duty_spread(loop: LinearLoop, sigma_estimate_m: float) -> float:
    """Std of the duty χ [-] that σ(ŝ) causes, √(c X cᵀ) with c = ``duty_row``; NaN if unstable.
    The loop is linear only while χ stays clear of its limits (``shortest_phase_samples``)."""
    x = stationary_covariance(loop, sigma_estimate_m)
    return float("nan") if x is None else float(np.sqrt(loop.duty_row @ x @ loop.duty_row))


def spread_relative_error(loop: LinearLoop, n_periods: int) -> float:
    """Relative standard error of the true gap's std measured over ``n_periods`` periods [-]:
    √(Σₖ ρₖ² / (2 N)) for a Gaussian stationary process (Bartlett), ρₖ = (Aᵏ X)₀₀ / X₀₀ the
    closed loop's autocorrelation at lag k, summed over k = −∞ … ∞ until it has decayed."""
    x = stationary_covariance(loop, 1.0)
    if x is None:
        return float("nan")
    lags = int(np.ceil(np.log(AUTOCORRELATION_FLOOR) / np.log(spectral_radius(loop))))
    column, squares = x[:, 0], 0.0
    for _ in range(lags):
        column = loop.closed @ column                           # (Aᵏ X) e₀
        squares += (column[0] / x[0, 0]) ** 2
    return float(np.sqrt((1.0 + 2.0 * squares) / (2.0 * n_periods)))


def stable_bandwidths_rad_s(setup: SelfSensingSetup, control_: LevitationControl, gap_m: float
                            ) -> tuple[float, float]:
    """(lowest, highest) ω_c [rad/s] for which the linearised loop is stable (NaN: none found
    inside ``BANDWIDTH_SEARCH_RAD_S``), each edge refined by Brent's method."""
    def margin(bandwidth: float) -> float:
        return spectral_radius(linear_loop(setup, control_._replace(bandwidth_rad_s=bandwidth), gap_m)) - 1.0
    grid = np.geomspace(*BANDWIDTH_SEARCH_RAD_S, 120)
    values = np.array([margin(w) for w in grid])
    stable = np.flatnonzero(values < 0)
    if not len(stable):
        return float("nan"), float("nan")
    first, last = stable[0], stable[-1]
    low = grid[0] if first == 0 else scipy.optimize.brentq(margin, grid[first - 1], grid[first], xtol=1e-6)
    high = grid[-1] if last == len(grid) - 1 else scipy.optimize.brentq(margin, grid[last], grid[last + 1],
                                                                         xtol=1e-6)
    return float(low), float(high)


class LevitatedLoop(SelfSensingLoop):
    """Period-by-period runs of ``run_levitated``: the ball starts at rest at the reference
    with the coil in the prescribed loop's periodic steady state; a run that leaves the
    reference stops for good with ``stop_message``."""

    def __init__(self, setup: SelfSensingSetup, control_: LevitationControl, seed: int = 0):
        super().__init__(setup, seed)
        self.control = control_
        gap = gap_at(0.0, setup.gap_1_m, setup.gap_2_m, self.pwm_run.hold_s, setup.transition_s,
                     TRAJECTORIES.index(setup.trajectory))
        inductance_h = float(setup.rig.inductance_h(gap))
        self.state = np.array([self.flux, gap, 0.0, 0.0, 0.0, 0.0, inductance_h, gap, self.flux / inductance_h])

    def run(self, n_periods: int, raw_samples: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(per-period rows, raw samples) as ``SelfSensingLoop.run``; no rows once stopped."""
        if self.stop_message:
            n_periods = 0
        n = self.setup.samples_per_period
        out = np.empty((n_periods, len(COLUMNS)))
        raw = np.empty((min(raw_samples, n_periods * n), 5))
        done = run_levitated(self.period, n_periods, self.state, self.constants, self.pwm_run, self.control,
                             self.rng_state, out, raw)
        self.period += done
        self.flux = float(self.state[0])
        if done < n_periods:
            self.stop_message = self.stopped(out[done - 1])
        return out[:done], raw[:min(len(raw), done * n)]

    def stopped(self, row: np.ndarray) -> str:
        """Why the run stopped: where the ball went and what the analysis says of ω_c."""
        reference = row[COLUMNS.index("gap_reference_m")]
        low, high = stable_bandwidths_rad_s(self.setup, self.control, reference)
        hz = self.control.bandwidth_rad_s / (2 * np.pi)
        gap = self.state[1]
        where = "towards the core" if gap < reference else "away from the core"
        return (f"Stopped at t = {self.period * self.setup.period_s:.3f} s: the ball left its reference "
                f"{reference * 1e3:.2f} mm by more than {self.control.stop_deviation_m * 1e3:g} mm ({where}). "
                f"The loop on ŝ is unstable at ω_c = 2π·{hz:.1f} Hz: the linearised analysis (ŝ one PWM period "
                f"old and averaged over it) keeps it stable only for 2π·{low / (2 * np.pi):.1f} … "
                f"{high / (2 * np.pi):.1f} Hz. Lower the bandwidth and press Reset.")

    def retuned(self, setup: SelfSensingSetup) -> LevitatedLoop:
        """The same run (period, coil, ball, controller, noise stream) with a new set-up."""
        loop = LevitatedLoop(setup, self.control)
        loop.period, loop.flux, loop.rng_state = self.period, self.flux, self.rng_state
        loop.state, loop.stop_message = self.state, self.stop_message
        return loop
