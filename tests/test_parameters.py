"""SI values of the controls (lab_modules/parameters.py): the factor of each unit, unknown units
refused, and a conversion that is the same multiplication as the hand-written one."""

from __future__ import annotations

import numpy as np
import pytest

from lab_modules.parameters import Parameter, ParameterError, in_si, si_factor

LAG = Parameter("sensor_lag_us", "Sensor lag", "µs", 200.0, 0.0, 1000.0)
NODE = Parameter("node_position_mm", "Node x", "mm", "-0.5", choices=("-0.5", "0", "0.5"))
LAW = Parameter("force_law", "Force law", "", "nonlinear", choices=("nonlinear", "linear"))
CURRENT = Parameter("current_noise_a", "Current noise", "A", 1.87, 0.0, 5.0)


@pytest.mark.parametrize("unit, factor", [
    ("µs", 1e-6), ("ms", 1e-3), ("µm", 1e-6), ("mm", 1e-3), ("mA", 1e-3), ("mV", 1e-3), ("%", 1e-2),
    ("A/mm", 1e3), ("A/(mm·s)", 1e3), ("A·s/mm", 1e3), ("N/µm", 1e6), ("N·mm²/A²", 1e-6), ("mm⁴/A⁴", 1e-12),
    ("rpm", 2 * np.pi / 60), ("rpm/s", 2 * np.pi / 60),
])
def test_scaled_units_have_their_factor(unit, factor):
    assert si_factor(unit) == factor


@pytest.mark.parametrize("unit", ["s", "A", "Ω", "V/V", "rad/s", "m²/s³", "1/(m·s)²", "(N/A)²", "s²/m²",
                                  "A·s/m", "", "×", "samples", "SI"])
def test_si_units_and_plain_numbers_keep_their_value(unit):
    assert si_factor(unit) == 1.0


@pytest.mark.parametrize("unit", ["mH", "kN", "µm/s", "mm²", "inch", "Ω·mm", "1"])
def test_a_scaled_unit_nobody_listed_is_refused_by_name(unit):
    with pytest.raises(ParameterError, match=f"unit '{unit}' has no known SI factor"):
        si_factor(unit)


def test_the_si_value_is_the_hand_conversions_multiplication():
    """``x * 1e-6`` and ``x / 1e6`` differ in the last bit for some x; the SI value is the former."""
    shown = np.linspace(0.0, 1000.0, 2001)
    assert any(x * 1e-6 != x / 1e6 for x in shown)
    assert all(LAG.si({"sensor_lag_us": x}) == x * 1e-6 for x in shown)


def test_a_choice_among_numbers_is_read_as_a_number_and_words_are_left_out():
    values = {"sensor_lag_us": 50.0, "node_position_mm": "0.5", "force_law": "linear", "current_noise_a": 2.0}
    assert NODE.numeric and not LAW.numeric
    assert in_si((LAG, NODE, LAW, CURRENT), values) == {"sensor_lag_us": 50.0 * 1e-6,
                                                         "node_position_mm": 0.5 * 1e-3,
                                                         "current_noise_a": 2.0}


def test_controls_absent_from_the_values_are_left_out():
    assert in_si((LAG, CURRENT), {"current_noise_a": 1.0}) == {"current_noise_a": 1.0}
