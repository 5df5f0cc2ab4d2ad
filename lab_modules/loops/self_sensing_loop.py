"""The compiled 1 µs simulation of paper 001: coil, full-bridge PWM and the
ripple estimator, one PWM period per outer step.

Within a period of ``n`` samples (T_pwm = n T_a) the bridge applies +v_bat
for the first ``n_on`` samples (charging phase I, duty χ = n_on / n) and
−v_bat for the rest (phase II).  The coil flux follows eq. 3, dψ/dt = v − R i
with i = ψ / L(s(t)) (this contains eq. 4's motion term), integrated exactly
for the inductance frozen at the middle of each sample step.  The ball moves
on a prescribed trajectory (no position controller): the paper's Fig. 2-7
change the operating point between 4 and 6 mm with transition time 0.3 s.
A per-period duty controller makes the mean current of the next period the
equilibrium current of the gap at its end (the ball's weight; no position
feedback).  Current and voltage are measured with the errors of eq. 19 and
23 and white noise; each phase's window (trimmed by a few samples at both
ends, away from the switching edges) is fitted by the estimator of
``estimators.ripple_inductance``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit, uint64

from lab_modules.estimators.ripple_inductance import average, fit_half_period
from lab_modules.plants.self_sensing_ball import (
    GRAVITY,
    RIG,
    SelfSensingBall,
    gap_from_inductance,
    inductance,
    inductance_slope,
    position_sensitivity,
)

#: Per-period output columns of ``run_periods`` (SI units).
COLUMNS = (
    "gap_true_m", "inductance_true_h", "duty", "inductance_1_h", "inductance_2_h", "inductance_mean_h",
    "sigma_current_1_a", "sigma_current_2_a", "sigma_inductance_1_h", "sigma_inductance_2_h",
    "sigma_inductance_mean_h", "gap_estimated_m", "sigma_gap_m", "delta_current_1_a", "delta_current_2_a",
    "weight_1", "weight_2", "mean_current_1_a", "mean_current_2_a", "current_mean_true_a",
    "inductance_1_true_h", "inductance_2_true_h", "gap_reference_m", "gap_fed_back_m", "current_command_a",
    "velocity_m_s",
)
COLUMN = {name: k for k, name in enumerate(COLUMNS)}
TRAJECTORIES = ("4-6-4 mm", "fixed at gap 1", "fixed at gap 2")
HOLD_S = 0.35            # time at each operating point between the transitions


class PwmRun(NamedTuple):
    """The set-up of one run as ``run_periods`` takes it (``SelfSensingSetup.pwm_run``), SI units."""

    samples_per_period: int         # n: T_pwm = n T_a [-]
    sample_time_s: float            # T_a [s]
    battery_voltage_v: float        # v_bat [V], applied as ±v_bat by the bridge
    resistance_ohm: float           # coil resistance R [Ω]
    resistance_estimate_ohm: float  # R̂ of eq. 7 [Ω], negative for the printed v_j + R i_j
    current_gain: float             # μ of eq. 19 (i = μ i_m) [-]
    voltage_gain: float             # η of eq. 19 (v = η v_m) [-]
    current_offset_a: float         # Δi of eq. 23 [A]
    voltage_offset_v: float         # Δv of eq. 23 [V]
    sigma_current_a: float          # σ of the current measurement's white noise [A]
    sigma_voltage_v: float          # σ of the voltage measurement's white noise [V]
    trim_samples: int               # samples left out at both ends of each phase's window [-]
    gap_1_m: float                  # first operating point's gap [m]
    gap_2_m: float                  # second operating point's gap [m]
    transition_s: float             # duration of a move between them [s]
    trajectory: int                 # index in ``TRAJECTORIES`` (``gap_at``'s mode)
    ball_mass_kg: float             # the ball's mass [kg] (its weight sets the duty)
    dof_sign: float                 # −1: eq. 28 with M − d degrees of freedom; +1: the printed M + d [-]
    hold_s: float                   # time at each operating point between the moves [s]


@njit(cache=True, nogil=True, inline="always")
def _rotate(x, k):
    return (x << uint64(k)) | (x >> uint64(64 - k))


@njit(cache=True, nogil=True)
def _uniform(state):
    """xoshiro256** (Blackman and Vigna): a double in (0, 1]."""
    s0, s1, s2, s3 = state[0], state[1], state[2], state[3]
    result = _rotate(s1 * uint64(5), 7) * uint64(9)
    t = s1 << uint64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotate(s3, 45)
    state[0], state[1], state[2], state[3] = s0, s1, s2, s3
    return ((result >> uint64(11)) + uint64(1)) * (1.0 / 9007199254740992.0)


@njit(cache=True, nogil=True)
def fill_normal(state, out):
    """Standard normal numbers into ``out`` (Marsaglia's polar method), compiled and free of
    the GIL: numpy's generator would hold the GIL for most of a run's time."""
    n = out.size
    k = 0
    while k < n:
        u = 2.0 * _uniform(state) - 1.0
        v = 2.0 * _uniform(state) - 1.0
        s = u * u + v * v
        if s >= 1.0 or s == 0.0:
            continue
        f = math.sqrt(-2.0 * math.log(s) / s)
        out[k] = u * f
        if k + 1 < n:
            out[k + 1] = v * f
        k += 2


@njit(cache=True, nogil=True)
def gap_at(t, gap_1, gap_2, hold_s, transition_s, mode):
    """Prescribed gap [m]: mode 0 repeats hold at gap_1, minimum-jerk move to gap_2
    (10τ³ − 15τ⁴ + 6τ⁵ over ``transition_s``), hold, move back; 1/2: fixed at gap_1/gap_2."""
    if mode == 1:
        return gap_1
    if mode == 2:
        return gap_2
    cycle = 2.0 * (hold_s + transition_s)
    t = t - cycle * np.floor(t / cycle)
    if t < hold_s:
        return gap_1
    t -= hold_s
    if t < transition_s:
        tau = t / transition_s
        return gap_1 + (gap_2 - gap_1) * tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    t -= transition_s
    if t < hold_s:
        return gap_2
    tau = (t - hold_s) / transition_s
    return gap_2 + (gap_1 - gap_2) * tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


@njit(cache=True, nogil=True)
def run_periods(first_period, n_periods, flux, constants, setup, rng_state, out, raw):
    """Simulate ``n_periods`` PWM periods from period index ``first_period`` and coil
    flux ``flux`` [Wb]; returns the flux at the end.

    constants: ``SelfSensingBall.constants``.  setup: ``PwmRun``.  rng_state: the
    xoshiro256** state of the measurement noise, in place.  out: (n_periods, len(COLUMNS)).
    raw: (rows, 5) filled with the first rows samples (time, true current, measured current,
    measured voltage, true voltage)."""
    n = setup.samples_per_period
    ts = setup.sample_time_s
    v_bat = setup.battery_voltage_v
    r = setup.resistance_ohm
    mu = setup.current_gain
    eta = setup.voltage_gain
    di = setup.current_offset_a
    dv = setup.voltage_offset_v
    sig_i = setup.sigma_current_a
    sig_v = setup.sigma_voltage_v
    trim = setup.trim_samples
    gap_1 = setup.gap_1_m
    gap_2 = setup.gap_2_m
    transition = setup.transition_s
    mode = setup.trajectory
    weight = setup.ball_mass_kg * GRAVITY
    hold = setup.hold_s
    period_s = n * ts
    current_m = np.empty(n + 1)
    voltage_m = np.empty(n + 1)
    fit_1 = np.empty(7)
    fit_2 = np.empty(7)
    noise = np.empty(2 * n + 2)
    true_i = np.empty(n)
    inv_mu = 1.0 / mu
    inv_eta = 1.0 / eta
    min_on = 2 * trim + 3
    for p in range(n_periods):
        t0 = (first_period + p) * period_s
        l0 = inductance(gap_at(t0, gap_1, gap_2, hold, transition, mode), constants)
        lm = inductance(gap_at(t0 + 0.5 * period_s, gap_1, gap_2, hold, transition, mode), constants)
        gap_end = gap_at(t0 + period_s, gap_1, gap_2, hold, transition, mode)
        l1 = inductance(gap_end, constants)
        # duty: the mean current of this period is the equilibrium current at its end.
        # Triangle: mean = start current + Δi/2, so aim the end current at i_eq − Δi/2.
        i_eq = np.sqrt(2.0 * weight / abs(inductance_slope(gap_end, constants)))
        chi = duty_for_mean_current(flux / l0, l0, i_eq, l1, r, v_bat, period_s)
        n_on = int(np.rint(chi * n))
        n_on = max(min_on, min(n - min_on, n_on))
        # Quadratic interpolation of L(t) through the start, middle and end of the period.
        a2 = 2.0 * (l1 - 2.0 * lm + l0)
        a1 = l1 - l0 - a2 * 0.5
        if sig_i > 0.0 or sig_v > 0.0:
            fill_normal(rng_state, noise)
        else:
            noise[:] = 0.0
        l_sum = 0.0
        l_1_sum = 0.0
        l_2_sum = 0.0
        for k in range(n + 1):
            x = k / n
            lk = l0 + x * (a1 + 0.5 * a2 * x)
            current = flux / lk
            v = v_bat if k < n_on else -v_bat
            current_m[k] = current * inv_mu - di + sig_i * noise[2 * k]
            voltage_m[k] = v * inv_eta - dv + sig_v * noise[2 * k + 1]
            if k == n:
                break
            true_i[k] = current
            l_sum += lk
            if trim <= k <= n_on - trim:
                l_1_sum += lk
            elif n_on + trim <= k <= n - trim:
                l_2_sum += lk
            xm = (k + 0.5) / n
            a = r * ts / (l0 + xm * (a1 + 0.5 * a2 * xm))
            step = ts * (1.0 - a * (0.5 - a * (1.0 / 6.0 - a / 24.0)))      # (1 − e^(−a)) L / R, frozen L
            flux = flux * (1.0 - a * step / ts) + v * step
        store_raw(raw, p, t0, ts, true_i, current_m, voltage_m, n_on, v_bat)
        row = out[p]
        estimate_period(current_m, voltage_m, n_on, setup, constants, fit_1, fit_2, row)
        row[0] = gap_at(t0 + 0.5 * period_s, gap_1, gap_2, hold, transition, mode)
        row[1] = l_sum / n
        row[19] = np.mean(true_i)
        row[20] = l_1_sum / (n_on - 2 * trim + 1)
        row[21] = l_2_sum / (n - n_on - 2 * trim + 1)
        row[22] = row[0]
        row[23] = np.nan                                # no position feedback
        row[24] = i_eq
        row[25] = (gap_end - gap_at(t0, gap_1, gap_2, hold, transition, mode)) / period_s
    return flux


@njit(cache=True, nogil=True)
def duty_for_mean_current(current_start_a, inductance_start_h, target_a, inductance_end_h, resistance_ohm,
                          battery_voltage_v, period_s):
    """The duty χ whose period has the mean current ``target_a`` [A], from the current and
    inductance at its start and the inductance at its end [H] (a one-period dead-beat on the flux).
    Triangle: mean = start current + Δi/2, so the end current aims at target − Δi/2 and
    ∫(v − R i) dt = (2χ − 1) v_bat T − R ī T is the flux the period must add."""
    chi_0 = 0.5 * (1.0 + resistance_ohm * target_a / battery_voltage_v)
    ripple = (battery_voltage_v - resistance_ohm * target_a) * chi_0 * period_s / inductance_end_h
    i_end = target_a - 0.5 * ripple
    needed = inductance_end_h * i_end - inductance_start_h * current_start_a     # ∫(v − R i) dt [Wb]
    mean_current = 0.5 * (current_start_a + i_end) + 0.5 * ripple
    return 0.5 * (1.0 + (needed / period_s + resistance_ohm * mean_current) / battery_voltage_v)


@njit(cache=True, nogil=True)
def store_raw(raw, p, t0, sample_time_s, true_i, current_m, voltage_m, n_on, battery_voltage_v):
    """The samples of period ``p`` (of n = len(true_i)) into the rows of ``raw`` that have room:
    time [s], true current [A], measured current [A], measured voltage [V], applied voltage [V]."""
    n = true_i.size
    for k in range(min(n, raw.shape[0] - p * n)):
        raw[p * n + k, 0] = t0 + k * sample_time_s
        raw[p * n + k, 1] = true_i[k]
        raw[p * n + k, 2] = current_m[k]
        raw[p * n + k, 3] = voltage_m[k]
        raw[p * n + k, 4] = battery_voltage_v if k < n_on else -battery_voltage_v


@njit(cache=True, nogil=True)
def estimate_period(current_m, voltage_m, n_on, setup, constants, fit_1, fit_2, row):
    """The estimator's columns of one period's row (duty, eq. 7-10 and 28-30 per phase, eq. 18
    and 31, eq. 2 and 32) from its measured samples (n + 1, the last one the next period's first)."""
    n = setup.samples_per_period
    trim = setup.trim_samples
    r_hat = setup.resistance_estimate_ohm
    ts = setup.sample_time_s
    fit_half_period(current_m, voltage_m, trim, n_on - trim, r_hat, ts, setup.dof_sign, fit_1)
    fit_half_period(current_m, voltage_m, n_on + trim, n - trim, r_hat, ts, setup.dof_sign, fit_2)
    l_bar, var_bar, w_1, w_2 = average(fit_1, fit_2)
    row[2] = n_on / n
    row[3] = fit_1[0]
    row[4] = fit_2[0]
    row[5] = l_bar
    row[6] = np.sqrt(fit_1[2])
    row[7] = np.sqrt(fit_2[2])
    row[8] = np.sqrt(fit_1[1])
    row[9] = np.sqrt(fit_2[1])
    row[10] = np.sqrt(var_bar)
    row[11] = gap_from_inductance(l_bar, constants)
    row[12] = position_sensitivity(l_bar, constants) * row[10]
    row[13] = fit_1[3]
    row[14] = fit_2[3]
    row[15] = w_1
    row[16] = w_2
    row[17] = fit_1[4]
    row[18] = fit_2[4]


@dataclass(frozen=True)
class SelfSensingSetup:
    """One experiment of paper 001 (SI units)."""

    rig: SelfSensingBall = RIG
    sample_time_s: float = 1e-6            # T_a
    samples_per_period: int = 1024         # T_pwm = 1024 T_a
    resistance_ratio: float = 1.0          # R̂ / R
    printed_eq7: bool = False              # the misprint v_j + R i_j of eq. 7
    current_gain: float = 1.0              # μ of eq. 19 (i = μ i_m)
    voltage_gain: float = 1.0              # η of eq. 19 (v = η v_m)
    current_offset_a: float = 0.0          # Δi of eq. 23 (i = i_m + Δi)
    voltage_offset_v: float = 0.0          # Δv of eq. 23 (v = v_m + Δv)
    sigma_current_a: float = 0.0
    sigma_voltage_v: float = 0.0
    trim_samples: int = 8
    gap_1_m: float = 4e-3
    gap_2_m: float = 6e-3
    transition_s: float = 0.3
    trajectory: str = "4-6-4 mm"
    battery_voltage_v: float | None = None  # None: the rig's 11.4 V
    printed_dof: bool = False              # eq. 28 with the printed M + d

    @property
    def period_s(self) -> float:
        return self.samples_per_period * self.sample_time_s

    def pwm_run(self) -> PwmRun:
        """The set-up as ``run_periods`` takes it (numbers of fixed types: one compiled kernel serves all)."""
        r = self.rig.coil_resistance_ohm
        return PwmRun(samples_per_period=int(self.samples_per_period), sample_time_s=float(self.sample_time_s),
                      battery_voltage_v=float(self.battery_voltage_v or self.rig.battery_voltage_v),
                      resistance_ohm=float(r),
                      resistance_estimate_ohm=float(self.resistance_ratio * r * (-1.0 if self.printed_eq7 else 1.0)),
                      current_gain=float(self.current_gain), voltage_gain=float(self.voltage_gain),
                      current_offset_a=float(self.current_offset_a), voltage_offset_v=float(self.voltage_offset_v),
                      sigma_current_a=float(self.sigma_current_a), sigma_voltage_v=float(self.sigma_voltage_v),
                      trim_samples=int(self.trim_samples), gap_1_m=float(self.gap_1_m), gap_2_m=float(self.gap_2_m),
                      transition_s=float(self.transition_s), trajectory=TRAJECTORIES.index(self.trajectory),
                      ball_mass_kg=float(self.rig.ball_mass_kg), dof_sign=1.0 if self.printed_dof else -1.0,
                      hold_s=HOLD_S)


class SelfSensingLoop:
    """Period-by-period runs of ``run_periods``, with its own noise generator."""

    def __init__(self, setup: SelfSensingSetup, seed: int = 0):
        self.setup = setup
        self.constants = setup.rig.constants()
        self.pwm_run = setup.pwm_run()
        self.rng_state = np.random.default_rng(seed).integers(1, 2**63, 4, dtype=np.uint64)
        self.period = 0
        self.stop_message = ""          # a prescribed motion never stops
        gap = gap_at(0.0, setup.gap_1_m, setup.gap_2_m, HOLD_S, setup.transition_s,
                     TRAJECTORIES.index(setup.trajectory))
        # start in the periodic steady state of the first period's duty: the bottom of the ripple
        i_eq = float(setup.rig.equilibrium_current_a(gap))
        v_bat = self.pwm_run.battery_voltage_v
        r = setup.rig.coil_resistance_ohm
        chi = 0.5 * (1.0 + r * i_eq / v_bat)
        inductance_h = float(setup.rig.inductance_h(gap))
        ripple = (v_bat - r * i_eq) * chi * setup.period_s / inductance_h
        self.flux = inductance_h * (i_eq - 0.5 * ripple)

    def run(self, n_periods: int, raw_samples: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(per-period rows (n_periods, COLUMNS), raw samples (raw_samples, 5))."""
        n = self.setup.samples_per_period
        out = np.empty((n_periods, len(COLUMNS)))
        raw = np.empty((min(raw_samples, n_periods * n), 5))
        self.flux = run_periods(self.period, n_periods, self.flux, self.constants, self.pwm_run, self.rng_state,
                                 out, raw)
        self.period += n_periods
        return out, raw

    def retuned(self, setup: SelfSensingSetup) -> SelfSensingLoop:
        """The same run (period, coil flux, noise stream) carried on with a new set-up of the
        same sample time and period length."""
        loop = SelfSensingLoop(setup)
        loop.period, loop.flux, loop.rng_state = self.period, self.flux, self.rng_state
        return loop
