"""Command line (app/cli.py): listing, headless runs, bad input, and the
paper's headline claims on the default run."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from lab_modules.exercises.kalman_noise import EXERCISE

REPO = Path(__file__).resolve().parents[1]
PARAMETERS = {p.name: p for p in EXERCISE.parameters}

METRIC_KEYS = {
    "rms_displacement_measured_feedback_um", "rms_displacement_estimated_feedback_um",
    "oscillation_reduction_percent", "steady_state_kalman_gain", "closed_loop_poles",
    "max_gain_factor_measured", "max_gain_factor_estimated",
}


def run_app(*argv, timeout=120):
    """``python -m app ARGV`` in a fresh interpreter at the repository root."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "app", *argv], check=False, cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout)


def range_tokens(name):
    """Strings the error message must show for parameter ``name``: its valid values."""
    p = PARAMETERS[name]
    return list(p.choices) if p.choices else [f"{p.minimum:.10g}", f"{p.maximum:.10g}"]


# -- list ------------------------------------------------------------------------

def test_list_json_describes_every_parameter():
    """``list --json`` (subprocess): kalman_noise with every parameter's name,
    unit, description, default and its range (min <= default <= max) or choices."""
    result = run_app("list", "--json")
    assert result.returncode == 0, result.stderr
    exercises = {e["name"]: e for e in json.loads(result.stdout)}
    assert "kalman_noise" in exercises
    parameters = exercises["kalman_noise"]["parameters"]
    names = [p["name"] for p in parameters]
    assert len(names) == len(set(names))
    assert set(names) == set(PARAMETERS)
    for p in parameters:
        assert {"name", "unit", "default", "description"} <= p.keys(), p["name"]
        assert isinstance(p["description"], str) and p["description"], p["name"]
        if "choices" in p:
            assert p["default"] in p["choices"], p["name"]
        else:
            assert p["min"] <= p["default"] <= p["max"], p["name"]


# -- run -------------------------------------------------------------------------

def test_run_json_prints_one_object_with_model_and_metrics(capsys):
    """``run kalman_noise --json --duration 0.5``: one JSON object with the
    resolved parameters, a model with consistent shapes and all metrics."""
    assert main(["run", "kalman_noise", "--json", "--duration", "0.5"]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    result = json.loads(out)                   # the whole of stdout is one object
    assert isinstance(result, dict)
    assert result["parameters"] == EXERCISE.resolve({})

    model = result["model"]
    A, B, C, Q, R = (np.array(model[k], dtype=float) for k in "ABCQR")
    n = A.shape[0]
    assert n in (3, 4) and A.shape == (n, n) and len(model["states"]) == n
    assert B.shape == (n, 1)
    assert C.shape == (2, n)
    assert Q.shape == (n, n) and np.allclose(Q, Q.T) and np.all(np.diag(Q) >= 0)
    assert R.shape == (2, 2) and np.all(np.diag(R) > 0)

    metrics = result["metrics"]
    assert METRIC_KEYS <= metrics.keys()
    assert metrics["duration_s"] == pytest.approx(0.5)
    assert np.array(metrics["steady_state_kalman_gain"]).shape == (n, 2)
    poles = metrics["closed_loop_poles"]
    assert len(poles) >= n
    for pole in poles:
        assert len(pole) == 2 and all(isinstance(v, float) and math.isfinite(v) for v in pole)
    assert max(math.hypot(re, im) for re, im in poles) < 1.0          # default loop is stable
    for key in METRIC_KEYS - {"steady_state_kalman_gain", "closed_loop_poles"}:
        assert isinstance(metrics[key], float) and math.isfinite(metrics[key]), key


# -- bad input -------------------------------------------------------------------

BAD_INPUT = [  # (argv after "run", strings the one error line must contain)
    pytest.param(["no_such_exercise"], ["no_such_exercise", "kalman_noise"], id="unknown-exercise"),
    pytest.param(["kalman_noise", "--set", "bogus=1"], ["bogus", "sensor_noise_um"], id="unknown-parameter"),
    pytest.param(["kalman_noise", "--set", "sensor_noise_um=abc"],
                 ["sensor_noise_um", *range_tokens("sensor_noise_um")], id="non-number"),
    pytest.param(["kalman_noise", "--set", "sensor_noise_um="],
                 ["sensor_noise_um", *range_tokens("sensor_noise_um")], id="empty-value"),
    pytest.param(["kalman_noise", "--set", "pid_gain=nan"],
                 ["pid_gain", *range_tokens("pid_gain")], id="nan"),
    pytest.param(["kalman_noise", "--set", "gain_factor=inf"],
                 ["gain_factor", *range_tokens("gain_factor")], id="inf"),
    pytest.param(["kalman_noise", "--set", "integral_time_ms=-inf"],
                 ["integral_time_ms", *range_tokens("integral_time_ms")], id="minus-inf"),
    pytest.param(["kalman_noise", "--set", "filter_r_position=1e400"],
                 ["filter_r_position", *range_tokens("filter_r_position")], id="overflow"),
    pytest.param(["kalman_noise", "--set", "gain_factor=4.5"],
                 ["gain_factor", *range_tokens("gain_factor")], id="above-range"),
    pytest.param(["kalman_noise", "--set", "sensor_lag_us=-1"],
                 ["sensor_lag_us", *range_tokens("sensor_lag_us")], id="below-range"),
    pytest.param(["kalman_noise", "--set", "feedback=both"],
                 ["feedback", *range_tokens("feedback")], id="bad-choice"),
    pytest.param(["kalman_noise", "--set", "force_law=quadratic"],
                 ["force_law", *range_tokens("force_law")], id="bad-choice-force-law"),
    pytest.param(["kalman_noise", "--seed", "1.5"], ["seed", *range_tokens("seed")], id="non-integer-seed"),
    pytest.param(["kalman_noise", "--set", "sensor_noise_um"], ["sensor_noise_um", "NAME=VALUE"],
                 id="set-without-equals"),
    pytest.param(["kalman_noise", "--set", "=3"], ["NAME=VALUE"], id="set-without-name"),
    pytest.param(["kalman_noise", "--duration", "abc"], ["--duration", "0.01", "60"], id="duration-text"),
    pytest.param(["kalman_noise", "--duration", "nan"], ["--duration", "0.01", "60"], id="duration-nan"),
    pytest.param(["kalman_noise", "--duration", "0"], ["--duration", "0.01", "60"], id="duration-zero"),
    pytest.param(["kalman_noise", "--duration", "1e9"], ["--duration", "0.01", "60"], id="duration-huge"),
    pytest.param(["kalman_noise", "--data", "recording.csv"], ["kalman_noise", "--data"], id="data-not-taken"),
    pytest.param(["kalman_noise", "--set", "data=x.csv"], ["data", "--data FILE"], id="data-as-parameter"),
]


@pytest.mark.parametrize("argv, must_contain", BAD_INPUT)
def test_bad_input_exits_2_with_one_line(argv, must_contain, capsys):
    """Exit status 2, nothing on stdout, exactly one stderr line naming the
    parameter (or problem) and its valid range."""
    assert main(["run", *argv]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.endswith("\n") and len(err.splitlines()) == 1, err
    for token in must_contain:
        assert token in err, f"{token!r} not in {err!r}"


@pytest.mark.parametrize("argv, must_contain", [
    (["--clients", "0"], ["--clients 0", "1 ... 1000"]),
    (["--clients", "5", "--workers", "0"], ["--workers 0", "1 ... 16"]),
    (["--clients", "5", "--steps", "0"], ["--steps 0", "1 ... 50"]),
    (["--clients", "5", "--window", "-1"], ["--window -1", "1 ... 120"]),
    (["--clients", "5", "--slider-every", "-2"], ["--slider-every -2", "0 ... 100"]),
    (["--clients", "5", "--runs", "11"], ["--runs 11", "1 ... 10"]),
])
def test_bad_bench_options_exit_2_with_one_line_before_any_server(argv, must_contain, capsys):
    assert main(["bench", *argv]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1 and all(token in err for token in must_contain), err


def test_unknown_start_exercise_exits_2_before_serving(capsys):
    assert main(["--exercise", "no_such_exercise", "--port", "1"]) == 2
    _, err = capsys.readouterr()
    assert len(err.splitlines()) == 1 and "no_such_exercise" in err and "kalman_noise" in err


def test_bad_input_in_a_real_process():
    """The same contract through ``python -m app`` (the process exit status)."""
    result = run_app("run", "kalman_noise", "--set", "gain_factor=nan")
    assert result.returncode == 2
    assert result.stdout == ""
    assert len(result.stderr.splitlines()) == 1 and "gain_factor" in result.stderr


# -- the paper's headline claims on the default run -----------------------------

@pytest.fixture(scope="module")
def default_run():
    result = run_app("run", "kalman_noise", "--json", "--duration", "2")
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)["metrics"]


def test_default_run_reduces_noise_driven_motion(default_run):
    """Paper §II / Fig. 3: feeding back the estimate cuts the noise-driven rotor
    oscillation by about 80 %.  For the true rotor no controller can: the lower
    bound for any causal controller allows at most about 57 % against the PID on
    the measurement.  The filter's estimate gets within 10 points of that."""
    assert default_run["status_measured_feedback"] == "ok"
    assert default_run["status_estimated_feedback"] == "ok"
    assert default_run["max_possible_reduction_percent"] < 60.0
    assert default_run["oscillation_reduction_percent"] > default_run["max_possible_reduction_percent"] - 10.0
    assert default_run["rms_displacement_estimated_feedback_um"] > 0.95 * default_run[
        "rms_displacement_lower_bound_um"]


def test_default_run_reduces_what_the_rig_can_see_by_the_papers_80_percent(default_run):
    """Paper §II, Fig. 3: the rig sees the rotor only through its control
    variable and its coil current.  Both drop by about 80 % (the paper's
    figure) when the estimate is fed back: the position signal the controller
    acts on (measured vs estimated) and the coil current's noise."""
    assert default_run["fed_back_position_reduction_percent"] >= 75.0
    assert default_run["current_noise_reduction_percent"] >= 75.0


def test_default_run_allows_higher_gains_with_the_filter(default_run):
    """Paper §II: with the estimate fed back the PID gains could rise by about 75 %."""
    ratio = default_run["max_gain_factor_estimated"] / default_run["max_gain_factor_measured"]
    assert ratio >= 1.75


@pytest.mark.parametrize("source", ["measured", "estimated"])
def test_default_run_simulation_agrees_with_linear_prediction(default_run, source):
    """The 2 s simulation (nonlinear plant) is within 15 % of the Lyapunov prediction."""
    simulated = default_run[f"rms_displacement_{source}_feedback_um"]
    predicted = default_run[f"predicted_rms_displacement_{source}_feedback_um"]
    assert simulated == pytest.approx(predicted, rel=0.15)
