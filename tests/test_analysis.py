"""Linear analysis of the loop (lab_modules.analysis, controllers) against
python-control and against the time simulation."""

import control
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from lab_modules import analysis
from lab_modules.controllers.pid import pid
from lab_modules.exercises.kalman_noise import EXERCISE, setup
from lab_modules.loops import radial_axis_loop
from lab_modules.loops.radial_axis_experiment import AxisSimulation
from lab_modules.plants.radial_bearing import RIG

T = RIG.sample_time_s
LAGS_S = [0.0, 200e-6]
GAIN_FACTORS = [1.0, 1.6]


def kalman_noise_setup(**changes):
    return setup(EXERCISE.resolve({})).with_changes(**changes)


def pole_distance(a, b):
    """Largest distance between two pole sets after optimal one-to-one pairing
    (robust where sorting would mis-pair nearly equal real parts)."""
    a, b = np.asarray(a, dtype=complex), np.asarray(b, dtype=complex)
    assert a.shape == b.shape, f"{a.size} poles vs {b.size}"
    distance = np.abs(a[:, None] - b[None, :])
    rows, cols = linear_sum_assignment(distance)
    return distance[rows, cols].max()


def position_channel(axis, undelayed=False):
    """Discrete plant i_ref [V] -> position [V]: the sensor output K_mx x_d, or K_mx x."""
    A, B, C = (np.asarray(M) for M in (axis.model.A, axis.model.B, axis.model.C))
    output = C[:1].copy()
    if undelayed:
        output = np.zeros_like(output)
        output[0, 0] = RIG.position_sensor_gain_v_per_m
    return control.ss(A, B[:, :1], output, 0, axis.model.dt)


# -- closed-loop poles -----------------------------------------------------------

@pytest.mark.parametrize("gain_factor", GAIN_FACTORS)
@pytest.mark.parametrize("sensor_lag_s", LAGS_S)
def test_measured_feedback_poles_match_python_control(sensor_lag_s, gain_factor):
    """loop_poles (measured feedback) = poles of feedback(P_pos C, 1), i.e.
    e = K_mx r - y, negative feedback (within 1e-8); positive feedback differs."""
    axis = kalman_noise_setup(sensor_lag_s=sensor_lag_s)
    controller = gain_factor * axis.controller
    ours = analysis.loop_poles(axis.loop(use_estimate=False, gain_factor=gain_factor))
    plant = position_channel(axis)
    expected = control.feedback(plant * controller, 1).poles()
    assert pole_distance(ours, expected) <= 1e-8
    wrong_sign = control.feedback(plant * controller, 1, sign=+1).poles()
    assert pole_distance(ours, wrong_sign) > 1e-3


@pytest.mark.parametrize("gain_factor", GAIN_FACTORS)
@pytest.mark.parametrize("sensor_lag_s", LAGS_S)
def test_estimated_feedback_poles_obey_separation_principle(sensor_lag_s, gain_factor):
    """loop_poles (estimated feedback) = poles of the PID loop on the undelayed
    position K_mx x  ∪  eig(A - A K C) of the filter error (within 1e-6)."""
    axis = kalman_noise_setup(sensor_lag_s=sensor_lag_s)
    A, C = np.asarray(axis.model.A), np.asarray(axis.model.C)
    K, _ = axis.steady_state_filter
    ours = analysis.loop_poles(axis.loop(use_estimate=True, gain_factor=gain_factor))
    control_poles = control.feedback(position_channel(axis, undelayed=True)
                                     * (gain_factor * axis.controller), 1).poles()
    filter_poles = np.linalg.eigvals(A - A @ K @ C)
    assert pole_distance(ours, np.concatenate([control_poles, filter_poles])) <= 1e-6


@pytest.mark.parametrize("use_estimate", [False, True])
@pytest.mark.parametrize("sensor_lag_s", LAGS_S)
def test_paper_pid_loop_is_stable_and_tracks_reference(sensor_lag_s, use_estimate):
    """The paper's PID (K = 0.65, T_I = 50 ms, T_D = 3 ms) stabilises the axis:
    all loop poles inside the unit circle, and integral action gives a DC gain
    of 1 (within 1e-6) from the reference to the rotor position."""
    axis = kalman_noise_setup(sensor_lag_s=sensor_lag_s)
    loop = axis.loop(use_estimate=use_estimate)
    assert np.max(np.abs(analysis.loop_poles(loop))) < 1.0
    dc = control.dcgain(loop.system[analysis.LOOP_OUTPUTS.index("x_m"),
                                     analysis.LOOP_INPUTS.index("reference_m")])
    assert float(np.real(dc)) == pytest.approx(1.0, abs=1e-6)


# -- noise-driven RMS against simulation ------------------------------------------

@pytest.mark.parametrize("use_estimate", [False, True], ids=["measured-fb", "estimated-fb"])
def test_noise_rms_matches_long_linear_simulation(use_estimate):
    """noise_rms (discrete Lyapunov equation) agrees with 20 s of the compiled
    loop on the linear plant (seed fixed, first 0.1 s dropped) within 10 %,
    for the rotor position, the amplifier reference and the coil current."""
    axis = kalman_noise_setup(nonlinear=False, use_estimate=use_estimate)
    predicted = axis.noise_rms()
    sim = AxisSimulation(axis, seed=7)
    trace = sim.advance(round(20.0 / T))
    assert sim.status == radial_axis_loop.OK
    trace = trace[round(0.1 / T):]
    columns = {"x_m": "x_true_m", "current_reference_v": "current_reference_v", "current_a": "current_a"}
    for output, column in columns.items():
        signal = trace[:, 1 + radial_axis_loop.TRACE_COLUMNS.index(column)]
        simulated = np.sqrt(np.mean(signal**2))
        assert simulated == pytest.approx(predicted[output], rel=0.10), output


def test_noise_rms_is_infinite_for_unstable_loop():
    """A gain far beyond the stable range gives inf for every output."""
    axis = kalman_noise_setup()
    assert np.max(np.abs(analysis.loop_poles(axis.loop(gain_factor=20.0)))) > 1.0
    assert all(np.isinf(v) for v in axis.noise_rms(gain_factor=20.0).values())


# -- the PID controller ------------------------------------------------------------

PID_SETTINGS = [  # K [V/V], T_I, T_D, tau [s]
    (0.65, 50e-3, 3e-3, 300e-6),     # paper §IV with the lab's tau = T_D / 10
    (2.0, 10e-3, 1e-3, 100e-6),
    (0.1, 500e-3, 10e-3, 2e-3),
]


@pytest.mark.parametrize("gain, ti, td, tau", PID_SETTINGS)
def test_pid_follows_continuous_transfer_function(gain, ti, td, tau):
    """controllers.pid vs K (1 + 1/(T_I s) + T_D s/(tau s + 1)) at frequencies
    well below the 10 kHz Nyquist frequency: within 2 % (complex relative error)."""
    discrete = pid(gain, ti, td, tau, T)
    assert discrete.dt == pytest.approx(T)
    s = control.tf("s")
    continuous = gain * (1 + 1 / (ti * s) + td * s / (tau * s + 1))
    for f_hz in [0.1, 1.0, 10.0, 100.0, 300.0]:
        w = 2 * np.pi * f_hz
        c_discrete = complex(discrete(np.exp(1j * w * T)))
        c_continuous = complex(continuous(1j * w))
        assert abs(c_discrete / c_continuous - 1) <= 0.02, f"{f_hz} Hz"


@pytest.mark.parametrize("gain, ti, td, tau", PID_SETTINGS)
def test_pid_dc_and_high_frequency_limits(gain, ti, td, tau):
    """Integral action: a pole at z = 1 (1e-12) and |C| -> K/(T_I w) at 0.01 Hz (2 %).
    High frequency: Tustin maps s = inf to z = -1, so C(-1) = K (1 + T_D/tau) (1e-9)."""
    discrete = pid(gain, ti, td, tau, T)
    assert np.min(np.abs(discrete.poles() - 1.0)) <= 1e-12
    w = 2 * np.pi * 0.01
    assert abs(complex(discrete(np.exp(1j * w * T)))) == pytest.approx(gain / (ti * w), rel=0.02)
    assert complex(discrete(-1.0)).real == pytest.approx(gain * (1 + td / tau), rel=1e-9)
    assert abs(complex(discrete(-1.0)).imag) <= 1e-9 * gain * (1 + td / tau)


def test_displacement_floor_is_the_unstable_poles_price():
    """Without process noise and sensor lag the bound is sigma_x sqrt(exp(2aT) - 1)
    for the unstable pole a = sqrt(k_x / m) (a scalar Riccati equation)."""
    axis = kalman_noise_setup(process_force_n=0.0, process_current_a=0.0, sensor_lag_s=0.0)
    a = np.sqrt(RIG.kx_n_per_m / RIG.equivalent_mass_kg)
    expected = axis.sensor_noise_m * np.sqrt(np.exp(2 * a * T) - 1)
    assert axis.displacement_floor_m == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("use_estimate", [False, True])
@pytest.mark.parametrize("gain_factor", [0.8, 1.0, 1.5])
def test_no_loop_beats_the_displacement_floor(use_estimate, gain_factor):
    """The bound holds for the PID on either feedback source (Lyapunov RMS >= bound)."""
    axis = kalman_noise_setup(use_estimate=use_estimate)
    assert axis.noise_rms(gain_factor=gain_factor)["x_m"] >= axis.displacement_floor_m


@pytest.mark.parametrize("use_estimate", [False, True])
def test_noise_spectrum_integrates_to_the_lyapunov_variance(use_estimate):
    """Parseval: the one-sided density of x over 0 ... Nyquist has the area noise_rms(x)^2."""
    axis = kalman_noise_setup(use_estimate=use_estimate)
    variances = axis.noise_variances
    loop = axis.loop()
    frequencies_hz = np.linspace(0.0, 0.4999 / T, 20001)
    density = analysis.noise_spectrum(loop, variances, frequencies_hz) ** 2
    area = np.sum(0.5 * (density[1:] + density[:-1]) * np.diff(frequencies_hz))
    assert np.sqrt(area) == pytest.approx(analysis.noise_rms(loop, variances)["x_m"], rel=1e-6)
