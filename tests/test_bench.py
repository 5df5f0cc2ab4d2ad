"""``python -m app bench``: the compiled loop and the filterpy loop it is compared with
compute the same estimates (no speed is asserted: speed belongs to the benchmark)."""

import math

import pytest

from app.commands import bench


@pytest.mark.parametrize("use_estimate", [False, True])
def test_filterpy_loop_reproduces_the_compiled_loop(use_estimate):
    reference = bench.filterpy_loop(bench.benchmark_simulation(use_estimate, seed=3), 2000)
    compiled = bench.benchmark_simulation(use_estimate, seed=3).advance(2000)
    estimate = compiled[:, 1 + bench.radial_axis_loop.TRACE_COLUMNS.index("x_estimated_m")]
    scale = max(abs(reference).max(), 1e-30)
    assert abs(estimate - reference).max() / scale < 1e-9


def test_bench_reports_every_figure():
    result = bench.run(seconds=0.02)
    assert result["max_relative_estimate_difference_vs_filterpy"] < 1e-9
    for key in ("realtime_factor_one_core", "realtime_factor_per_cpu_second", "realtime_factor_two_threads",
                "parallel_speedup_two_threads", "cpu_time_per_wall_time_two_threads", "speedup_vs_filterpy_loop"):
        assert math.isfinite(result[key]) and result[key] > 0, key
    assert result["thrust_liftoff"]["realtime_factor_one_core"] > 0
