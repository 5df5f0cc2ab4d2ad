"""Linear analysis of the loop (lab_modules.analysis, controllers) against
python-control and against the time simulation."""

import control
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from lab_modules import analysis, loop_responses
from lab_modules.controllers.pid import pid
from lab_modules.controllers.pid import setpoint_filter as pid_setpoint_filter
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


# -- step responses, frequency-response peak, reference filter (trade-off sweeps) --------

@pytest.mark.parametrize("use_estimate", [False, True])
@pytest.mark.parametrize("input_name", ["reference_m", "disturbance_n"])
def test_compiled_step_response_equals_python_control(use_estimate, input_name):
    """``loop_responses.step_response`` (compiled recursion) = python-control's
    ``step_response`` of the same loop, every output, to 1e-9 of its peak."""
    loop = kalman_noise_setup(use_estimate=use_estimate).loop()
    n = 2000
    ours = loop_responses.step_response(loop, input_name, n)
    j = analysis.LOOP_INPUTS.index(input_name)
    theirs = control.step_response(loop.system[:, j], T=np.arange(n) * T).outputs   # (outputs, time)
    theirs = np.asarray(theirs).reshape(len(analysis.LOOP_OUTPUTS), n).T
    scale = np.max(np.abs(theirs), axis=0)
    assert np.all(scale > 0)
    assert np.max(np.abs(ours - theirs) / scale) <= 1e-9


@pytest.mark.parametrize("use_estimate", [False, True])
def test_peak_gain_is_the_largest_frequency_response(use_estimate):
    """``loop_responses.peak_gain`` of force -> position: not below python-control's
    magnitude anywhere on a dense grid (within 1e-6), and equal to it at the
    frequency it reports; ``frequency_gain`` = python-control to 1e-9."""
    loop = kalman_noise_setup(use_estimate=use_estimate).loop()
    grid = np.geomspace(0.5, 0.499 / T, 4000)
    j, i = analysis.LOOP_INPUTS.index("disturbance_n"), analysis.LOOP_OUTPUTS.index("x_m")
    reference = control.frequency_response(loop.system[i, j], 2 * np.pi * grid).magnitude.ravel()
    ours = loop_responses.frequency_gain(loop, "disturbance_n", "x_m", grid)
    np.testing.assert_allclose(ours, reference, rtol=1e-9)
    peak, at_hz = loop_responses.peak_gain(loop, "disturbance_n", "x_m")
    assert peak >= reference.max() * (1 - 1e-6)
    there = control.frequency_response(loop.system[i, j], [2 * np.pi * at_hz]).magnitude.ravel()[0]
    assert there == pytest.approx(peak, rel=1e-9)


@pytest.mark.parametrize("td", [1e-3, 3e-3])
def test_setpoint_filter_makes_the_pid_an_i_pd(td):
    """C(z) F(z) = C_I(z): the PID behind ``setpoint_filter`` passes the reference
    through its integral part only (python-control frequency responses, 1e-8)."""
    gain, ti, tau = 0.65, 0.05, td / 10
    controller = pid(gain, ti, td, tau, T)
    s = control.tf("s")
    integral = control.c2d(gain / (ti * s), T, method="tustin")
    omega = 2 * np.pi * np.geomspace(1.0, 9000.0, 50)
    through = control.frequency_response(controller * pid_setpoint_filter(ti, td, tau, T), omega).complex.ravel()
    expected = control.frequency_response(integral, omega).complex.ravel()
    np.testing.assert_allclose(through, expected, rtol=1e-8)


def test_reference_filter_changes_only_the_reference_channel():
    """``with_reference_filter``: the reference channel becomes loop × filter
    (python-control series), the other inputs and the loop poles are unchanged."""
    axis = kalman_noise_setup(use_estimate=True)
    loop = axis.loop()
    F = pid_setpoint_filter(0.05, 3e-3, 3e-4, T)
    filtered = analysis.with_reference_filter(loop, F)
    omega = 2 * np.pi * np.geomspace(1.0, 9000.0, 40)
    for name in analysis.LOOP_INPUTS:
        j = analysis.LOOP_INPUTS.index(name)
        ours = control.frequency_response(filtered.system[:, j], omega).complex
        channel = loop.system[:, j] * F if name == "reference_m" else loop.system[:, j]
        theirs = control.frequency_response(channel, omega).complex
        np.testing.assert_allclose(np.asarray(ours), np.asarray(theirs), rtol=1e-7, atol=1e-18)
    assert pole_distance(analysis.loop_poles(filtered), analysis.loop_poles(loop)) <= 1e-12


@pytest.mark.parametrize("use_estimate", [False, True])
def test_closed_loop_matrices_are_the_python_control_loop(use_estimate):
    """``closed_loop_matrices`` (the sweeps' loops) holds the very matrices of ``closed_loop``, and
    ``with_reference_filter`` keeps each kind, with the same matrices."""
    axis = kalman_noise_setup(use_estimate=use_estimate)
    arguments = (axis.model, axis.controller, axis.steady_state_filter[0], use_estimate)
    light, full = analysis.closed_loop_matrices(*arguments), analysis.closed_loop(*arguments)
    prefilter = pid_setpoint_filter(50e-3, 3e-3, 0.3e-3, T)
    light_filtered, full_filtered = (analysis.with_reference_filter(loop, prefilter) for loop in (light, full))
    assert isinstance(light_filtered.system, analysis.Matrices)
    assert isinstance(full_filtered.system, control.StateSpace)
    for a, b in ((light, full), (light_filtered, full_filtered)):
        assert a.loop_states == b.loop_states and a.system.dt == b.system.dt
        for name in "ABCD":
            assert np.array_equal(getattr(a.system, name), np.asarray(getattr(b.system, name)))


def unit_step_outputs_twin(A, b, C, d, n_samples):
    """The plain twin of the compiled step recursions: y_k = C x_k + d, x_{k+1} = A x_k + b from x_0 = 0,
    each sum taken left to right from d_r or b_r (the order the kernels keep)."""
    def sum_from(start, terms):
        for term in terms:
            start += term
        return start
    x, y = np.zeros(A.shape[0]), np.empty((n_samples, C.shape[0]))
    for k in range(n_samples):
        y[k] = [sum_from(d[r], C[r] * x) for r in range(C.shape[0])]
        x = np.array([sum_from(b[r], A[r] * x) for r in range(A.shape[0])])
    return y


@pytest.mark.parametrize("prefiltered", [False, True])
@pytest.mark.parametrize("use_estimate", [False, True])
def test_compiled_step_responses_equal_their_plain_twin_to_the_last_bit(use_estimate, prefiltered):
    """``step_response`` and ``step_responses`` (two inputs in one pass) = the plain recursion, bit for
    bit, on loops with an even and an odd number of states (the paired kernel's last row)."""
    loop = kalman_noise_setup(use_estimate=use_estimate).loop()
    if prefiltered:                     # a first-order reference filter: one state more, an odd number
        loop = analysis.with_reference_filter(loop, control.ss([[0.5]], [[0.5]], [[1.0]], [[0.0]], T))
    A, B, C, D = (np.asarray(M, dtype=float) for M in (loop.system.A, loop.system.B, loop.system.C, loop.system.D))
    assert A.shape[0] % 2 == int(prefiltered)
    n = 300
    names = ("disturbance_n", "reference_m")
    twins = [unit_step_outputs_twin(A, B[:, j], C, D[:, j], n) for j in map(analysis.LOOP_INPUTS.index, names)]
    assert np.max(np.abs(twins[1])) > 0 and np.max(np.abs(twins[0])) > 0
    for ours, twin in zip(loop_responses.step_responses(loop, names, n), twins):
        assert np.array_equal(ours, twin)
    for name, twin in zip(names, twins):
        assert np.array_equal(loop_responses.step_response(loop, name, n), twin)
