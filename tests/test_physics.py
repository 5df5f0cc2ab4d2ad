"""Physics of one bearing axis (lab_modules.plants.radial_bearing) against paper 000.

Paper: Schuhmann, Hofmann, Werner, "Adaptive Linear and Extended Kalman Filter
applied to AMB with Collocated Position Measuring", eq. 3-4, 10, 12 and the
Appendix.  The appendix numbers below are typed in from the paper, not taken
from the module.
"""

import numpy as np
import pytest
import scipy.signal

from lab_modules.plants.radial_bearing import RIG

# Appendix of paper 000
PAPER_KX_N_PER_M = 800310.0
PAPER_KI_N_PER_A = 128.6
PAPER_AIR_GAP_RANGE_M = (0.3e-3, 0.7e-3)
PAPER_SAMPLE_TIME_S = 50e-6

#: Central-difference steps.  f_m is exactly quadratic in i (eq. 10), so the
#: current derivative has no truncation error; in x the truncation error is
#: about (h_x / air gap)^2 ~ 1e-9 relative.
H_X_M = 1e-8
H_I_A = 1e-4


def central_difference_factors(x_m, i_a):
    """(k_x, k_i) of eq. 10 at (x, i) by central finite differences of RIG.magnetic_force."""
    f = RIG.magnetic_force
    kx = (f(x_m + H_X_M, i_a) - f(x_m - H_X_M, i_a)) / (2 * H_X_M)
    ki = (f(x_m, i_a + H_I_A) - f(x_m, i_a - H_I_A)) / (2 * H_I_A)
    return kx, ki


def test_force_law_linearised_at_centre_reproduces_appendix_factors():
    """Eq. 10 linearised at x = 0, i = 0 gives the appendix k_x and k_i (rtol 1e-6)."""
    kx, ki = central_difference_factors(0.0, 0.0)
    assert kx == pytest.approx(PAPER_KX_N_PER_M, rel=1e-6)
    assert ki == pytest.approx(PAPER_KI_N_PER_A, rel=1e-6)
    kx_analytic, ki_analytic = RIG.local_factors(0.0, 0.0)
    assert kx_analytic == pytest.approx(PAPER_KX_N_PER_M, rel=1e-6)
    assert ki_analytic == pytest.approx(PAPER_KI_N_PER_A, rel=1e-6)


def test_force_is_zero_at_centre_without_control_current():
    """The two magnets of the differential pair cancel at the centre (|f| < 1e-9 N)."""
    assert abs(RIG.magnetic_force(0.0, 0.0)) < 1e-9


@pytest.mark.parametrize("x_m, i_a", [
    (100e-6, 0.0), (-100e-6, 0.0), (0.0, 3.0), (0.0, -3.0),
    (100e-6, 3.0), (-100e-6, -3.0), (60e-6, -2.0), (-40e-6, 1.5),
])
def test_local_factors_equal_finite_differences_off_centre(x_m, i_a):
    """Analytic (k_x, k_i) of eq. 10 equal central differences within rtol 1e-5."""
    kx_fd, ki_fd = central_difference_factors(x_m, i_a)
    kx, ki = RIG.local_factors(x_m, i_a)
    assert kx == pytest.approx(kx_fd, rel=1e-5)
    assert ki == pytest.approx(ki_fd, rel=1e-5)


@pytest.mark.parametrize("x_m, i_a", [(100e-6, 0.0), (30e-6, 2.0), (-70e-6, 3.0)])
def test_force_law_is_odd(x_m, i_a):
    """A differential bearing is point-symmetric: f(-x, -i) = -f(x, i) (rtol 1e-12)."""
    assert RIG.magnetic_force(-x_m, -i_a) == pytest.approx(-RIG.magnetic_force(x_m, i_a), rel=1e-12)


def test_derived_air_gap_and_bias_current_are_plausible():
    """delta0 lies in the rated air-gap range; i0 is positive and below the current limit."""
    low, high = PAPER_AIR_GAP_RANGE_M
    assert low <= RIG.delta0_m <= high
    assert 0.0 < RIG.i0_a < RIG.current_limit_a


@pytest.mark.parametrize("sensor_lag_s", [0.0, 200e-6])
def test_continuous_model_poles(sensor_lag_s):
    """Open-loop poles of eq. 3-4 (and 12): +-sqrt(k_x/m), -1/T_a (and -1/T_mx); rtol 1e-9."""
    m, Ta = 21.5, 400e-6                       # appendix: equivalent mass, amplifier lag
    expected = [np.sqrt(PAPER_KX_N_PER_M / m), -np.sqrt(PAPER_KX_N_PER_M / m), -1.0 / Ta]
    if sensor_lag_s > 0:
        expected.append(-1.0 / sensor_lag_s)
    poles = np.linalg.eigvals(np.asarray(RIG.continuous_model(sensor_lag_s).A))
    np.testing.assert_allclose(np.sort(poles.real), np.sort(expected), rtol=1e-9)
    np.testing.assert_allclose(poles.imag, 0.0, atol=1e-9)


@pytest.mark.parametrize("sensor_lag_s", [0.0, 200e-6])
def test_discrete_model_is_zero_order_hold_of_continuous_model(sensor_lag_s):
    """discrete_model equals scipy's ZOH discretisation at T = 50 µs (rtol 1e-12)."""
    continuous = RIG.continuous_model(sensor_lag_s)
    discrete = RIG.discrete_model(sensor_lag_s)
    expected = scipy.signal.cont2discrete(
        tuple(np.asarray(M) for M in (continuous.A, continuous.B, continuous.C, continuous.D)),
        PAPER_SAMPLE_TIME_S, method="zoh")[:4]
    assert discrete.dt == pytest.approx(PAPER_SAMPLE_TIME_S, rel=1e-12)
    for got, want in zip((discrete.A, discrete.B, discrete.C, discrete.D), expected):
        got, want = np.asarray(got), np.asarray(want)
        assert got.shape == want.shape
        # atol only guards exact structural zeros against round-off of the largest entry
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * max(np.abs(want).max(), 1e-300))
