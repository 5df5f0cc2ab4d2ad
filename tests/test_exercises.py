"""Every registered exercise keeps the contract the app and the CLI rely on."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lab_modules.exercises import Analysis, Plot
from lab_modules.parameters import ParameterError, in_si, si_factor
from tests.example_exercise import contract_exercises

ROOT = Path(__file__).resolve().parent.parent
EXERCISES = contract_exercises()          # the registered ones and the tests' minimal example


@pytest.fixture(scope="module", params=sorted(EXERCISES))
def exercise(request):
    return EXERCISES[request.param]


def test_worksheet_exists_and_cites_its_source(exercise):
    text = (ROOT / "static" / "worksheets" / exercise.worksheet).read_text(encoding="utf-8")
    assert "Source" in text or "source" in text
    assert len(text) > 500


def test_parameters_are_described_with_units_and_ranges(exercise):
    names = [p.name for p in exercise.parameters]
    assert len(names) == len(set(names))
    for p in exercise.parameters:
        assert p.description and p.label
        if not p.choices:
            assert p.minimum <= p.default <= p.maximum, p.name
    values = exercise.resolve({})
    assert set(names) <= set(values)


def test_every_parameter_has_a_known_si_factor(exercise):
    """A unit outside ``parameters.SI_FACTORS`` passes only if it is SI or has no unit (else
    ParameterError names it); every numeric control's default reads in SI as default × factor."""
    values = exercise.resolve({})
    si = in_si(exercise.parameters, values)
    for p in exercise.parameters:
        factor = si_factor(p.unit)
        if p.numeric:
            assert si[p.name] == float(values[p.name]) * factor, p.name
        else:
            assert p.name not in si


def test_a_control_name_has_one_si_factor_in_every_exercise():
    """The helpers convert a control by its name with one definition (``_common`` with the shared
    radial-axis controls): the same name must scale alike wherever it appears (lqg_vs_pid's LQR
    weights and the maglev's process noise share names q_* but both are SI)."""
    factors: dict[str, set[float]] = {}
    for exercise in EXERCISES.values():
        for p in exercise.parameters:
            factors.setdefault(p.name, set()).add(si_factor(p.unit))
    assert {name: found for name, found in factors.items() if len(found) > 1} == {}


def test_out_of_range_value_names_parameter_and_range(exercise):
    numeric = next(p for p in exercise.parameters if not p.choices)
    with pytest.raises(ParameterError) as error:
        exercise.resolve({numeric.name: str(numeric.maximum * 10 + 1)})
    assert numeric.name in str(error.value)


def test_model_is_json(exercise):
    json.dumps(exercise.model(exercise.resolve({})))


def test_analysis_has_readouts_with_units(exercise):
    result = exercise.analyse(exercise.resolve({}))
    results = [result] if isinstance(result, Analysis) else list(result)
    assert results and all(isinstance(r, Analysis) for r in results)
    final = results[-1]
    assert final.readouts
    for label, value, unit in final.readouts:
        assert isinstance(label, str) and isinstance(unit, str)
        assert np.isscalar(value)
    for poles in final.poles.values():
        assert np.all(np.isfinite(np.asarray(poles)))
    for plot in final.plots:
        assert isinstance(plot, Plot)
        assert "[" in plot.x_label and "[" in plot.y_label, "plot axes carry units"
        assert all(len(y) == len(plot.x) for _, y, _ in plot.series)


def test_simulation_advances_with_a_time_column(exercise):
    simulation = exercise.simulation(exercise.resolve({}))
    n = max(int(0.01 / simulation.sample_time_s), 10)
    first, second = simulation.advance(n), simulation.advance(n)
    assert first.shape == (n, 1 + len(simulation.columns))
    assert simulation.status_message() == ""
    t = np.concatenate([first[:, 0], second[:, 0]])
    assert np.all(np.diff(t) > 0)
    assert np.allclose(np.diff(t), simulation.sample_time_s)
    for chart in exercise.charts:
        for series in chart.series:
            assert series.column in simulation.columns
        if chart.band:
            assert set(chart.band) <= set(simulation.columns)


def test_retune_keeps_running(exercise):
    values = exercise.resolve({})
    simulation = exercise.simulation(values)
    simulation.advance(10)
    retuned = exercise.retune(simulation, values)
    assert retuned.advance(10).shape[0] == 10


def test_actions_and_live_plots_keep_the_contract(exercise):
    """Optional hooks: every action names a method that yields or returns Analyses; live plots
    keep their number, series and length while the simulation runs (the app draws them into
    charts made once)."""
    for action in exercise.actions:
        assert action.label and callable(getattr(exercise, action.method))
    simulation = exercise.simulation(exercise.resolve({}))
    before = exercise.live_plots(simulation)
    simulation.advance(max(int(0.01 / simulation.sample_time_s), 10))
    after = exercise.live_plots(simulation)
    assert [(p.title.split("(")[0], len(p.x), len(p.series)) for p in before] == \
        [(p.title.split("(")[0], len(p.x), len(p.series)) for p in after]
    for plot in after:
        assert isinstance(plot, Plot) and "[" in plot.x_label and "[" in plot.y_label
        assert all(len(y) == len(plot.x) for _, y, _ in plot.series)
        assert len(plot.x) <= 2048, "a live plot streams a few thousand points at most"
