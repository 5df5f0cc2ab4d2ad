"""Headless edge cases of the classroom issue: start-up checks, recordings that
must be refused (one line naming line and column), ``--seed``/``--duration``
corner cases, no silent non-finite metrics, and saved experiments from the CLI."""

import json
import socket
import sys
from pathlib import Path

import pytest

from app.cli import main
from app.commands.headless import non_finite, stop_statuses
from tests.test_cli import run_app

REPO = Path(__file__).resolve().parents[1]
SHIPPED = (REPO / "static" / "recordings" / "maglev_leadlag.csv").read_text()


def _one_line_error(capsys, argv, status=2) -> str:
    assert main(argv) == status
    out, err = capsys.readouterr()
    assert out == "" and err.endswith("\n") and len(err.splitlines()) == 1, err
    return err


def _recording(tmp_path, edit) -> str:
    """The shipped recording with ``edit(lines)`` applied; returns its path."""
    lines = SHIPPED.splitlines()
    edit(lines)
    path = tmp_path / "edited.csv"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def _data_row(lines, k):
    """Index in ``lines`` of data row ``k`` (0-based) and its file line number."""
    first = next(i for i, line in enumerate(lines) if line.startswith("time_s")) + 1
    return first + k, first + k + 1


def test_data_from_dev_zero_is_refused_without_reading_it_all(capsys):
    err = _one_line_error(capsys, ["run", "maglev_tuning", "--data", "/dev/zero"])
    assert "larger than 20 MB" in err


@pytest.mark.parametrize("value, words", [("1e300", "outside the rig's range"), ("nan", "not a finite number"),
                                          ("-4", "outside the rig's range")])
def test_absurd_or_non_finite_values_name_line_and_column(tmp_path, capsys, value, words):
    def edit(lines):
        i, _ = _data_row(lines, 100)
        t, ref, _, u = lines[i].split(",")
        lines[i] = f"{t},{ref},{value},{u}"
    path = _recording(tmp_path, edit)
    _, line = _data_row(SHIPPED.splitlines(), 100)
    err = _one_line_error(capsys, ["run", "maglev_tuning", "--data", path])
    assert f"line {line}, column measured_position_mm" in err and words in err


def test_a_time_gap_is_refused(tmp_path, capsys):
    def edit(lines):
        start, _ = _data_row(lines, 2000)
        for i in range(start, len(lines)):
            t, *rest = lines[i].split(",")
            lines[i] = ",".join([f"{float(t) + 1000.0:.3f}", *rest])
    err = _one_line_error(capsys, ["run", "maglev_tuning", "--data", _recording(tmp_path, edit)])
    _, line = _data_row(SHIPPED.splitlines(), 2000)
    assert f"line {line}, column time_s" in err and "gap" in err


def test_too_few_samples_for_the_analysis(tmp_path, capsys):
    def edit(lines):
        i, _ = _data_row(lines, 50)
        del lines[i:]
    err = _one_line_error(capsys, ["run", "maglev_tuning", "--data", _recording(tmp_path, edit)])
    _, last_line = _data_row(SHIPPED.splitlines(), 49)
    assert f"line {last_line}" in err and "50 data rows" in err and "at least" in err


def test_seed_for_an_exercise_without_randomness(capsys):
    err = _one_line_error(capsys, ["run", "maglev_tuning", "--seed", "3"])
    assert "maglev_tuning" in err and "--seed" in err and "unknown parameter" not in err


def test_duration_nan_is_not_finite(capsys):
    assert "not finite" in _one_line_error(capsys, ["run", "kalman_noise", "--duration", "nan"])


def test_non_finite_metrics_need_a_status():
    metrics = {"a": 1.0, "b": {"c": [1.0, float("inf")]}, "status": "ok"}
    assert non_finite(metrics) == ["b.c.1"] and stop_statuses(metrics) == []
    assert stop_statuses({"status_x": "touched down"}) == ["status_x: touched down"]


def test_non_finite_metric_without_status_exits_1(monkeypatch, capsys):
    from lab_modules.exercises.kalman_noise import EXERCISE
    monkeypatch.setattr(type(EXERCISE), "metrics", lambda self, values, duration: {"x": float("nan")})
    assert main(["run", "kalman_noise", "--json"]) == 1
    out, err = capsys.readouterr()
    assert json.loads(out)["metrics"]["x"] == "nan"
    assert len(err.splitlines()) == 1 and "metric x is not finite" in err


def test_save_then_run_code_reproduces_the_run(tmp_path, capsys):
    data_dir = str(tmp_path / "data")
    assert main(["save", "kalman_noise", "--set", "gain_factor=1.5", "--set", "feedback=estimated",
                 "--data-dir", data_dir]) == 0
    code = capsys.readouterr().out.strip()
    assert len(code) == len("KN-7Q3M-X9TA-HPRW") and code.startswith("KN-")      # 12 random characters
    assert main(["run", "--code", code.lower(), "--json", "--duration", "0.3", "--data-dir", data_dir]) == 0
    by_code = json.loads(capsys.readouterr().out)
    assert main(["run", "kalman_noise", "--set", "gain_factor=1.5", "--set", "feedback=estimated",
                 "--json", "--duration", "0.3"]) == 0
    direct = json.loads(capsys.readouterr().out)
    assert by_code["code"] == code and by_code["parameters"] == direct["parameters"]
    assert by_code["metrics"] == direct["metrics"]
    err = _one_line_error(capsys, ["run", "--code", "KN-2222", "--data-dir", data_dir])
    assert "no experiment is saved under KN-2222" in err


def test_save_keeps_the_recording(tmp_path, capsys):
    data_dir = str(tmp_path / "data")
    path = REPO / "static" / "recordings" / "maglev_leadlag.csv"
    assert main(["save", "maglev_tuning", "--data", str(path), "--data-dir", data_dir]) == 0
    code = capsys.readouterr().out.strip()
    assert main(["run", "--code", code, "--json", "--data-dir", data_dir]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["parameters"]["data"] == "maglev_leadlag.csv" and result["metrics"]["status"] == "ok"


@pytest.mark.parametrize("argv, words", [(["--port", "99999"], "--port"), (["--port", "-5"], "--port"),
                                         (["--host", "256.1.1.1"], "256.1.1.1"),
                                         (["--token", "x y"], "--token")])
def test_bad_address_exits_2_at_once(argv, words):
    result = run_app(*argv, timeout=60)
    assert result.returncode == 2 and result.stdout == ""
    assert len(result.stderr.splitlines()) == 1 and words in result.stderr


def test_busy_port_is_refused_not_moved():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = run_app("--port", str(port), timeout=60)
    assert result.returncode == 2 and "in use" in result.stderr and str(port) in result.stderr
    assert len(result.stderr.splitlines()) == 1 and sys.executable
