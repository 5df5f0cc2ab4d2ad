"""The lab server a benchmark measures: started in a child process (one lab process, or several
behind HAProxy), and the CPU time of its process tree read from Linux ``/proc``."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def process_tree(pid: int) -> list[int]:
    """``pid`` and all its descendants (Linux ``/proc``)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    tree, todo = [], [pid]
    while todo:
        current = todo.pop()
        tree.append(current)
        todo += children.get(current, [])
    return tree


def cpu_seconds(pids: list[int]) -> float:
    """User + system CPU time [s] of processes so far (gone processes count 0)."""
    total = 0
    for pid in pids:
        with contextlib.suppress(OSError):
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


def wait_http(url: str, process: subprocess.Popen, timeout_s: float, log: Path) -> None:
    deadline = time.time() + timeout_s
    while True:
        try:
            urllib.request.urlopen(url, timeout=5).close()
            return
        except OSError:
            if process.poll() is not None or time.time() > deadline:
                raise RuntimeError(f"the lab server did not start: {log.read_text()[-2000:]}") from None
            time.sleep(0.3)


@contextlib.contextmanager
def lab_server(port: int, workers: int, exercise: str, log: Path,
               extra: tuple[str, ...] = (), timeout_s: float = 180.0) -> Iterator[subprocess.Popen]:
    """The lab on ``127.0.0.1:port`` in a child process (one lab process, or ``serve --workers``)."""
    command = [sys.executable, "-m", "app", "--host", "127.0.0.1", "--port", str(port), "--exercise", exercise]
    if workers > 1:
        command += ["serve", "--workers", str(workers)]
    command += list(extra)
    root = Path(os.environ.get("LAB_BENCH_ROOT", ROOT))   # another tree's lab, for before/after runs
    env = {**os.environ, "PYTHONPATH": str(root)}
    with log.open("w") as out:
        server = subprocess.Popen(command, cwd=root, stdout=out, stderr=subprocess.STDOUT, env=env)
        try:
            wait_http(f"http://127.0.0.1:{port}/", server, timeout_s, log)
            yield server
        finally:
            server.terminate()
            try:
                server.wait(timeout=20)
            except subprocess.TimeoutExpired:
                server.kill()
                server.wait()
