"""A lecture hall: ``python -m app serve --workers 2`` behind HAProxy, with headless tabs
(the load bench's websocket clients) and one real browser tab.

Scenario (one hall, in order): eight tabs spread over both workers, each with its own lab;
one worker is killed: the other worker's tabs go on undisturbed, a reconnecting tab gets a
lab from the survivor, and the supervisor starts the killed worker again; Ctrl-C leaves no
process behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.commands.lab_processes import process_tree, wait_http
from app.commands.load_bench import Tab, scope_titles
from app.hall import HAPROXY_MISSING, haproxy_config
from tests.conftest import Tab as BrowserTab
from tests.conftest import browser_only
from tests.wsclient import run_async

ROOT = Path(__file__).resolve().parent.parent
HAPROXY = shutil.which("haproxy")
needs_haproxy = pytest.mark.skipif(HAPROXY is None, reason="HAProxy is not installed (apt-get install haproxy)")
TABS = 8


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


@contextlib.contextmanager
def hall(port: int, tmp_path: Path, workers: int = 2):
    """``serve --workers`` on loopback; yields the supervisor process (stopped with SIGINT at the end)."""
    log = tmp_path / f"hall-{port}.log"
    command = [sys.executable, "-m", "app", "serve", "--workers", str(workers), "--port", str(port),
               "--worker-ports", str(port + 1), "--data-dir", str(tmp_path / "data")]
    with log.open("w") as out:
        supervisor = subprocess.Popen(command, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT,
                                      env={**os.environ, "PYTHONPATH": str(ROOT)})
        try:
            wait_http(f"http://127.0.0.1:{port}/", supervisor, 240, log)
            deadline = time.monotonic() + 30               # HAProxy's health checks see both workers
            while "open http" not in log.read_text() and time.monotonic() < deadline:
                time.sleep(0.2)
            time.sleep(3)
            yield supervisor
        finally:
            if supervisor.poll() is None:
                supervisor.send_signal(signal.SIGINT)
                supervisor.wait(timeout=30)


def _worker_pid(supervisor: subprocess.Popen, port: int) -> int:
    pids = [pid for pid in process_tree(supervisor.pid) if f"--port {port} " in _cmdline(pid) + " "]
    assert pids, f"no worker process on port {port}"
    return pids[0]


async def _until(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.1)


def _haproxy_accepts(config: str, folder: Path) -> None:
    """HAProxy's own check of ``config`` (skipped where HAProxy is not installed)."""
    if HAPROXY is None:
        pytest.skip("HAProxy is not installed")
    path = folder / "haproxy.cfg"
    path.write_text(config)
    checked = subprocess.run([HAPROXY, "-c", "-f", str(path)], check=False, capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout + checked.stderr


def test_generated_configuration_is_valid(tmp_path):
    config = haproxy_config("0.0.0.0", 8080, [("127.0.0.1", 8081), ("10.0.0.7", 8080)])
    assert "balance leastconn" in config and "timeout tunnel" in config and "check" in config
    _haproxy_accepts(config, tmp_path)


def test_haproxy_config_command():
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "app", "haproxy-config", "--backend", "10.0.0.5:8080",
                           "--backend", "10.0.0.6:8080", "--port", "80"], check=False, capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    assert "server lab1 10.0.0.5:8080" in done.stdout and "server lab2 10.0.0.6:8080" in done.stdout
    assert "bind 0.0.0.0:80" in done.stdout
    bad = subprocess.run([sys.executable, "-m", "app", "haproxy-config", "--backend", "nowhere"],
                         check=False, capture_output=True, text=True, env=env)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_missing_haproxy_is_one_line(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PATH": str(tmp_path)}     # no haproxy on PATH
    done = subprocess.run([sys.executable, "-m", "app", "serve", "--workers", "2", "--port", "8109"],
                          check=False, capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 1
    assert done.stderr.strip() == f"error: {HAPROXY_MISSING}"


@needs_haproxy
def test_two_workers_eight_tabs_crash_and_ctrl_c(tmp_path):
    port = 8150
    titles = scope_titles("kalman_noise")
    with hall(port, tmp_path) as supervisor:
        run_async(_scenario(supervisor, port, titles))
        tree = process_tree(supervisor.pid)
        assert len(tree) >= 4, "supervisor, two workers and HAProxy"
        supervisor.send_signal(signal.SIGINT)                 # Ctrl-C
        supervisor.wait(timeout=30)
        deadline = time.monotonic() + 10
        while any(Path(f"/proc/{pid}").exists() and _cmdline(pid) for pid in tree):
            assert time.monotonic() < deadline, [(pid, _cmdline(pid)) for pid in tree if _cmdline(pid)]
            time.sleep(0.2)


async def _scenario(supervisor: subprocess.Popen, port: int, titles) -> None:
    url = f"ws://127.0.0.1:{port}"
    stop = asyncio.Event()
    tabs = [Tab(url, titles, slider_every=0) for _ in range(TABS)]
    tasks = []
    for tab in tabs:
        tasks.append(asyncio.create_task(tab.run(stop)))
        await asyncio.sleep(0.3)
    try:
        await _until(lambda: all(len(t.scope_times) >= 3 for t in tabs), 120, "scope updates in every tab")
        by_worker: dict[str, list[Tab]] = {}
        for tab in tabs:
            by_worker.setdefault(tab.worker, []).append(tab)
        assert set(by_worker) == {"lab1", "lab2"}, {w: len(ts) for w, ts in by_worker.items()}
        assert all(len(ts) >= TABS // 2 - 1 for ts in by_worker.values()), \
            f"leastconn spreads the tabs: {({w: len(ts) for w, ts in by_worker.items()})}"
        assert len({t.slider for t in tabs}) == TABS and None not in {t.slider for t in tabs}, \
            "every tab has its own lab (its own controls)"

        killed = await asyncio.to_thread(_worker_pid, supervisor, port + 1)     # lab1
        os.kill(killed, signal.SIGKILL)
        kill_time = time.perf_counter()
        await _until(lambda: all(t.closed is not None for t in by_worker["lab1"]), 20,
                     "the killed worker's tabs to be disconnected")
        survivors = by_worker["lab2"]
        await asyncio.sleep(4.0)
        for tab in survivors:
            assert tab.closed is None, f"a tab on the surviving worker was disconnected: {tab.closed}"
            after = [t for t in tab.scope_times if t > kill_time]
            assert len(after) >= 8, f"the surviving worker's tab got {len(after)} scope updates in 4 s"

        again = Tab(url, titles, slider_every=0)                 # a tab of the killed worker reconnects
        tasks.append(asyncio.create_task(again.run(stop)))
        await _until(lambda: len(again.scope_times) >= 3, 60, "a lab for the reconnecting tab")
        assert again.worker == "lab2"

        restarted = await asyncio.to_thread(_wait_restart, supervisor, port + 1, killed)
        assert restarted != killed
    finally:
        stop.set()
        await asyncio.gather(*tasks, return_exceptions=True)


def _wait_restart(supervisor: subprocess.Popen, port: int, killed: int) -> int:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        with contextlib.suppress(AssertionError):
            pid = _worker_pid(supervisor, port)
            if pid != killed:
                wait_http(f"http://127.0.0.1:{port}/", supervisor, max(1.0, deadline - time.monotonic()),
                          Path("/dev/null"))
                return pid
        time.sleep(0.5)
    raise AssertionError("the supervisor did not restart the killed worker")


@needs_haproxy
@browser_only[0]
@browser_only[1]
def test_browser_through_haproxy(tmp_path, browser):
    """A real browser tab through HAProxy: readouts, both scope charts and the pole map, no console errors."""
    with hall(8170, tmp_path):
        tab = BrowserTab(browser, "http://127.0.0.1:8170")
        try:
            page = tab.page
            page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=90000)
            for title in scope_titles("kalman_noise"):
                page.get_by_text(title).first.wait_for(timeout=30000)
            assert page.locator("canvas").count() >= 3, "the 3D view and two scope charts"
            time.sleep(2.0)                                    # the scope streams for a while
            tab.open_panel_tab("Pole map")
            page.get_by_text("dominant poles", exact=False).first.wait_for(timeout=20000)
            assert not tab.errors, tab.errors
        finally:
            tab.page.close()


def test_configuration_caps_connections_per_process(tmp_path):
    from app.hall import PAGE_LOADS
    config = haproxy_config("0.0.0.0", 8080, [("127.0.0.1", 8081), ("127.0.0.1", 8082)], max_tabs=60)
    assert config.count(f"maxconn {60 + PAGE_LOADS}") == 2 and "timeout queue" in config
    assert "The lab is full" in config
    assert "    server lab1 10.0.0.5:8080\n" in haproxy_config("0.0.0.0", 80, [("10.0.0.5", 8080)])   # no cap
    _haproxy_accepts(config, tmp_path)


def test_a_restart_says_when_the_process_answers_again(monkeypatch, capsys):
    """The supervisor announces the restart delay plus what the process's last start took, and
    says when it answers again (a killed worker once announced 1 s and answered after 23 s)."""
    from app import hall
    now = [1000.0]
    answering = {"yes": False}
    monkeypatch.setattr(hall.time, "monotonic", lambda: now[0])
    monkeypatch.setattr(hall, "_ready", lambda url: answering["yes"])

    class Process:
        def __init__(self, status=None):
            self.status = status

        def poll(self):
            return self.status
    def start(self) -> None:                                   # what Worker.start records, without a process
        self.process, self.started, self.restart_at = Process(), now[0], None
    monkeypatch.setattr(hall.Worker, "start", start)
    worker = hall.Worker(1, 8081, ["lab"], {}, process=Process(), started=990.0, start_s=22.0)
    worker.process.status = -9                                 # killed 10 s after it started
    hall.supervise([worker])
    announced = capsys.readouterr().err
    assert "restarting in 1 s; it answers again in about 23 s (its last start took 22 s)" in announced
    now[0] += 1.0
    hall.supervise([worker])                                  # started again
    now[0] += 21.5
    hall.supervise([worker])
    assert capsys.readouterr().err == ""                       # not answering yet: nothing said
    answering["yes"] = True
    hall.supervise([worker])
    assert "answers again, 22 s after it exited" in capsys.readouterr().err
    assert worker.start_s == pytest.approx(21.5) and worker.exited_at is None
