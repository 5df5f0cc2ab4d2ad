"""A lab process (``python -m app``) runs OpenBLAS on one thread: its matrices are small and its
tabs' threads share the cores; OpenBLAS's helper threads spin while they wait (on a 2-core
server they doubled the CPU of an lqg_vs_pid analysis).  A value set in the environment is kept."""

from __future__ import annotations

import os
import subprocess
import sys

from tests.wsclient import REPO

PROBE = """
import runpy, sys, threadpoolctl
sys.argv = ["app", "list"]
try:
    runpy.run_module("app", run_name="__main__")
except SystemExit:
    pass
print(max(pool["num_threads"] for pool in threadpoolctl.threadpool_info() if pool["user_api"] == "blas"))
"""


def _blas_threads(**environment: str) -> int:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-c", PROBE], cwd=REPO, env={**env, **environment, "PYTHONPATH": str(REPO)},
                          capture_output=True, text=True, check=True, timeout=300)
    return int(done.stdout.split()[-1])


def test_a_lab_process_runs_blas_on_one_thread_unless_told_otherwise():
    assert _blas_threads() == 1
    assert _blas_threads(OPENBLAS_NUM_THREADS="2") == 2
