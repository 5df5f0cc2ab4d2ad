"""What the disk, a crowd or a curious student does to the classroom server (issue 24): raw
websocket clients on loopback, bounded in time and count.  Figures are printed (``pytest -s``)."""

from __future__ import annotations

import asyncio
import os
import resource
import shutil
import sqlite3
import subprocess
import sys
import time

import msgspec
import pytest

from tests.test_store_access import damaged_database
from tests.wsclient import CAMERA, READOUTS, REPO, RawTab, lab_process, lab_tab, run_async, url

pytestmark = pytest.mark.classroom

NOISE = "Position sensor noise σ [µm]"
SCOPE = "Rotor position [µm]"
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def _markdown(tab: RawTab, text: str) -> str:
    uuid = tab.find_containing("GuiMarkdownMessage", text)
    return tab.elements[uuid]["content"] if uuid else ""


async def _streams(tab: RawTab, seconds: float = 3.0) -> int:
    """Scope updates the tab received in the next ``seconds``."""
    scope = tab.find("GuiUplotMessage", SCOPE)
    start = time.perf_counter()
    await asyncio.sleep(seconds)
    return len(tab.update_times(scope, "data", start))


def _file_size_limit(pid: int, limit: int) -> None:
    """No file of process ``pid`` may grow beyond ``limit`` bytes (as on a full disk; Python
    ignores the SIGXFSZ that comes with it, so the write fails instead)."""
    resource.prlimit(pid, resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))   # soft: can be raised again


def test_a_full_disk_leaves_tabs_running_and_saves_again_with_room(tmp_path):
    """The database's files cannot grow after the first autosave: the tab keeps streaming and
    answering its slider, says in one line that its settings are kept, the log has the failure
    once and no traceback, a new tab still opens; with room again the retry saves."""
    port = 8461
    log = tmp_path / "server.log"
    data = tmp_path / "data"
    with lab_process(port, data_dir=data, log=log) as server:
        async def scenario():
            tab = await lab_tab(port)
            assert await tab.wait_for(lambda: _markdown(tab, "This tab is autosaved as"), 30)
            _file_size_limit(server.pid, max(path.stat().st_size for path in data.iterdir()))
            slider = tab.find("GuiSliderMessage", NOISE)
            await tab.set_value(slider, 1.3)
            await tab.wait_for(lambda: _markdown(tab, "Autosave failed"), 30)
            failed = _markdown(tab, "Autosave failed")
            updates_while_failing = await _streams(tab)
            readouts = _markdown(tab, READOUTS)
            await tab.set_value(slider, 1.6)
            answered = await tab.wait_for(lambda: _markdown(tab, READOUTS) != readouts, 30)
            second = await lab_tab(port)
            second_streams = await _streams(second)
            _file_size_limit(server.pid, resource.RLIM_INFINITY)
            again = await tab.wait_for(lambda: _markdown(tab, "Autosaved again"), 60)
            await second.close()
            await tab.close()
            return failed, updates_while_failing, answered, second_streams, again
        failed, updates, answered, second_streams, again = run_async(scenario())
    text = log.read_text()
    print(f"\nfull disk: tab line {failed!r}; scope {updates / 3:.1f} updates/s while failing; "
          f"a new tab {second_streams / 3:.1f} updates/s; saved again: {bool(again)}")
    assert "kept in this tab" in failed and updates > 0 and answered and second_streams > 0 and again
    assert text.count("saved experiments: the saved experiments cannot be written") == 1, text[-2000:]
    assert "works again" in text and "Traceback" not in text, text[-3000:]


def test_a_damaged_database_leaves_tabs_running(tmp_path):
    port = 8462
    log = tmp_path / "server.log"
    damaged_database(tmp_path / "data")
    with lab_process(port, data_dir=tmp_path / "data", log=log):
        async def scenario():
            tab = await lab_tab(port)
            failed = await tab.wait_for(lambda: _markdown(tab, "Autosave failed"), 30)
            updates = await _streams(tab)
            await tab.close()
            return failed, updates
        failed, updates = run_async(scenario())
    text = log.read_text()
    assert failed and updates > 0 and "Traceback" not in text, text[-3000:]
    assert text.count("database is damaged") == 1


def test_commands_on_a_bad_database_exit_2_with_one_line(tmp_path):
    from app.infra.store import Store, StoreUnavailable
    damaged, foreign = tmp_path / "damaged", tmp_path / "foreign"
    codes = damaged_database(damaged)
    store = Store(damaged)
    unreadable = []
    for code in codes:
        try:
            store.load(code)
        except StoreUnavailable:
            unreadable.append(code)
    store.close()
    foreign.mkdir()
    with sqlite3.connect(foreign / "lab.sqlite3") as db:
        db.execute("CREATE TABLE experiments (id INTEGER PRIMARY KEY, name TEXT)")
    runs = {
        "run --code, damaged": [sys.executable, "-m", "app", "run", "--code", unreadable[0], "--data-dir",
                                str(damaged)],
        "save, damaged": [sys.executable, "-m", "app", "save", "kalman_noise", "--data-dir", str(damaged)],
        "run --code, foreign": [sys.executable, "-m", "app", "run", "--code", "KN-ABCD", "--data-dir", str(foreign)],
        "save, foreign": [sys.executable, "-m", "app", "save", "kalman_noise", "--data-dir", str(foreign)],
        "serve, foreign": [sys.executable, "-m", "app", "--port", "8463", "--data-dir", str(foreign)],
    }
    for what, command in runs.items():
        done = subprocess.run(command, check=False, cwd=REPO, capture_output=True, text=True, env=ENV, timeout=300)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), (what, done.stderr)
        assert ("damaged" if "damaged" in what else "another layout") in lines[0], (what, lines[0])


def test_save_on_a_full_disk_exits_2_with_one_line(tmp_path):
    from app.infra.store import Store
    Store(tmp_path).close()
    limit = max(path.stat().st_size for path in tmp_path.iterdir())
    recording = tmp_path / "run.csv"
    recording.write_bytes((REPO / "static" / "recordings" / "maglev_leadlag.csv").read_bytes())
    done = subprocess.run([sys.executable, "-m", "app", "save", "maglev_tuning", "--data", str(recording),
                           "--data-dir", str(tmp_path)], check=False, cwd=REPO, capture_output=True, text=True,
                          env=ENV, timeout=300,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)))
    assert done.returncode == 2 and done.stderr.startswith("error: ") and "cannot be written" in done.stderr, \
        done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


async def _unfinished_uploads(port: int, count: int, part: bytes) -> RawTab:
    """A maglev_tuning tab that starts ``count`` uploads of 30 parts and sends 20 parts of each."""
    tab = await lab_tab(port)
    upload = tab.find("GuiUploadButtonMessage", "Load recording (CSV)")
    for k in range(count):
        await tab.send({"type": "FileTransferStartUpload", "source_component_uuid": upload, "transfer_uuid": f"t{k}",
                        "filename": "a.csv", "mime_type": "text/csv", "part_count": 30,
                        "size_bytes": 30 * len(part)})
        for i in range(20):
            await tab.send({"type": "FileTransferPart", "source_component_uuid": upload, "transfer_uuid": f"t{k}",
                            "part_index": i, "content": part})
    return tab


def test_unfinished_uploads_are_bounded_per_tab(tmp_path):
    """Two tabs each start 20 uploads of 15.7 MB and leave each at 10.5 MB: only each tab's newest
    is kept (before: 20 per tab, the process grew by 420 MB)."""
    from tests.wsclient import process_rss_mb
    port = 8464
    with lab_process(port, "--exercise", "maglev_tuning", data_dir=tmp_path, log=tmp_path / "server.log") as server:
        async def scenario():
            warm = await lab_tab(port)
            await asyncio.sleep(2)
            start = process_rss_mb(server.pid)
            part = b"1" * 512 * 1024
            tabs = [await _unfinished_uploads(port, 20, part) for _ in range(2)]
            await asyncio.sleep(5)
            grown = process_rss_mb(server.pid) - start
            for tab in (*tabs, warm):
                await tab.close()
            return grown
        grown = run_async(scenario())
    print(f"\nuploads: 2 tabs x 20 unfinished uploads of 10.5 MB: the server grew by {grown:.0f} MB")
    assert grown < 80


def test_tabs_beyond_max_tabs_wait_at_a_full_note_and_enter_when_a_place_frees(tmp_path):
    """``--max-tabs 2``: a third tab shows "The lab is full" and no lab; once a tab closes it
    gets its lab by itself; the log says the lab is full once."""
    port = 8465
    log = tmp_path / "server.log"
    with lab_process(port, "--max-tabs", "2", data_dir=tmp_path, log=log):
        async def scenario():
            first, second = await lab_tab(port), await lab_tab(port)
            third = await RawTab().connect(url(port))
            full = await third.wait_for(lambda: _markdown(third, "The lab is full"), 60)
            await asyncio.sleep(3)
            lab_while_full = bool(third.find("GuiUplotMessage", SCOPE) or third.find("GuiSliderMessage", NOISE))
            fourth = await RawTab().connect(url(port))
            assert await fourth.wait_for(lambda: _markdown(fourth, "The lab is full"), 60)
            await first.close()
            entered = await third.wait_for(lambda: third.find_containing("GuiMarkdownMessage", READOUTS), 120)
            note_gone = not _markdown(third, "The lab is full")
            still_waiting = _markdown(fourth, "The lab is full") and not fourth.find("GuiUplotMessage", SCOPE)
            for tab in (second, third, fourth):
                await tab.close()
            return full, lab_while_full, entered, note_gone, still_waiting
        full, lab_while_full, entered, note_gone, still_waiting = run_async(scenario())
    assert full and "ask your instructor" in full and not lab_while_full
    assert entered and note_gone and still_waiting
    assert log.read_text().count("the lab is full") == 1


@pytest.mark.skipif(shutil.which("haproxy") is None, reason="HAProxy is not installed (apt-get install haproxy)")
def test_a_full_hall_answers_with_the_full_page(tmp_path):
    """``serve --workers 2 --max-tabs 1``: HAProxy lets each process take its tab and
    ``PAGE_LOADS`` more connections (they wait at the full note in the tab), spread over both
    processes; beyond, a page load gets HAProxy's "The lab is full" page instead of a slow lab."""
    import urllib.error
    import urllib.request

    from app.commands.lab_processes import lab_server
    from app.hall import PAGE_LOADS
    port = 8470
    log = tmp_path / "hall.log"
    with lab_server(port, 2, "kalman_noise", log, ("--max-tabs", "1", "--data-dir", str(tmp_path / "data"))):
        async def scenario():
            tabs = [await RawTab().connect(url(port)) for _ in range(2 * (1 + PAGE_LOADS))]
            await asyncio.gather(*(t.wait_for(lambda t=t: t.find("GuiUplotMessage", SCOPE)
                                              or _markdown(t, "The lab is full"), 120) for t in tabs))
            labs = sum(1 for t in tabs if t.find("GuiUplotMessage", SCOPE))
            waiting = sum(1 for t in tabs if _markdown(t, "The lab is full"))

            def page() -> tuple[int, str]:
                try:
                    with urllib.request.urlopen(url(port), timeout=30) as answer:
                        return answer.status, ""
                except urllib.error.HTTPError as error:
                    return error.code, error.read().decode()
            status, text = await asyncio.to_thread(page)
            for tab in tabs:
                await tab.close()
            return labs, waiting, status, text
        labs, waiting, status, text = run_async(scenario())
    print(f"\nfull hall: {labs} labs, {waiting} tabs at the full note; the next page load: {status}")
    assert labs == 2 and waiting == 2 * PAGE_LOADS
    assert status == 503 and "The lab is full" in text and "ask your instructor" in text


def test_memory_returns_after_many_tabs_close(tmp_path):
    """30 tabs open at once and close: the server's memory comes back to within 20 % of what it
    was before them (after a first tab, which caches what every tab shares)."""
    from tests.wsclient import process_rss_mb
    port = 8466
    with lab_process(port, data_dir=tmp_path, log=tmp_path / "server.log") as server:
        async def scenario():
            warm = await lab_tab(port)
            await warm.close()
            await asyncio.sleep(5)
            start = process_rss_mb(server.pid)
            tabs = [await RawTab().connect(url(port)) for _ in range(30)]
            built = await asyncio.gather(*(t.wait_for(lambda t=t: t.find("GuiUplotMessage", SCOPE), 300)
                                           for t in tabs))
            await asyncio.sleep(3)
            peak = process_rss_mb(server.pid)
            for tab in tabs:
                await tab.close()
            await asyncio.sleep(8)
            return start, peak, process_rss_mb(server.pid), sum(map(bool, built))
        start, peak, after, built = run_async(scenario())
    print(f"\nmemory: {start:.0f} MB -> {built} tabs {peak:.0f} MB -> after they closed {after:.0f} MB "
          f"({100 * (after / start - 1):+.0f} %)")
    assert built == 30 and after <= 1.2 * start


async def _try_token(tab: RawTab, token: str) -> str:
    """Type ``token``, press Enter the lab; the gate's answer (or "" if the lab was built)."""
    field = tab.find("GuiTextMessage", "Class token")
    note = tab.find_containing("GuiMarkdownMessage", "⚠️")
    before = tab.elements[note]["content"] if note else ""
    await tab.set_value(field, token)
    await tab.set_value(tab.find("GuiButtonMessage", "Enter the lab"), True)

    def answered():
        uuid = tab.find_containing("GuiMarkdownMessage", "⚠️")
        text = tab.elements[uuid]["content"] if uuid else ""
        return text if text and text != before else tab.find("GuiUplotMessage", SCOPE) or tab.closed.is_set()
    result = await tab.wait_for(answered, 60)
    return result if isinstance(result, str) and result.startswith("⚠️") else ""


def test_wrong_class_tokens_are_throttled_across_connections(tmp_path):
    """Tabs from one address, reconnecting after every fifth wrong try (when the tab is closed),
    use up the address's allowance: ``TOKEN_TRIES_BURST`` plus what refills meanwhile; then a
    try is answered "too many" without being checked (until the next try refills); the log names
    the address once.  Before: every try of every connection was checked (35-45 guesses/s)."""
    from app.infra.access import TOKEN_TRIES_BURST, TOKEN_TRIES_PER_MINUTE
    port = 8467
    log = tmp_path / "server.log"
    with lab_process(port, "--token", "kalman42", data_dir=tmp_path, log=log):
        async def scenario():
            checked, start = 0, time.perf_counter()
            while True:
                tab = await RawTab().connect(url(port))
                await tab.wait_for(lambda t=tab: t.find("GuiTextMessage", "Class token"), 60)
                while not tab.closed.is_set():
                    answer = await _try_token(tab, f"wrong{checked}")
                    if "Too many wrong class tokens" in answer:
                        await tab.close()
                        return checked, time.perf_counter() - start, answer
                    checked += 1
                    assert checked < 40, "never throttled"
        checked, seconds, answer = run_async(scenario())
    allowance = TOKEN_TRIES_BURST + seconds * TOKEN_TRIES_PER_MINUTE / 60
    print(f"\ntoken guessing: throttled after {checked} checked wrong tries in {seconds:.0f} s")
    assert TOKEN_TRIES_BURST <= checked <= allowance + 1
    assert "tries left" not in answer                   # not checked, and not a try of the tab either
    assert log.read_text().count("too many failed tries from 127.0.0.1") == 1


@pytest.mark.skipif(shutil.which("haproxy") is None, reason="HAProxy is not installed (apt-get install haproxy)")
def test_the_hall_keeps_the_token_off_every_command_line(tmp_path):
    """``serve --workers 2`` with the token in the environment: no process of the hall shows it on
    its command line, and a tab through HAProxy is asked for it and let in."""
    from app.commands.lab_processes import lab_server, process_tree
    from app.infra.access import TOKEN_VARIABLE
    port = 8473
    token = "q7mz-k3pt-9hwa"
    os.environ[TOKEN_VARIABLE] = token
    try:
        with lab_server(port, 2, "kalman_noise", tmp_path / "hall.log", ("--data-dir", str(tmp_path / "data"))) \
                as supervisor:
            time.sleep(3)
            command_lines = [(REPO / "x").parent.joinpath("/proc", str(pid), "cmdline").read_bytes()
                             for pid in process_tree(supervisor.pid)]

            async def scenario():
                tab = await RawTab().connect(url(port))
                await tab.wait_for(lambda: tab.find("GuiTextMessage", "Class token"), 120)
                await _try_token(tab, token.upper())
                built = await tab.wait_for(lambda: tab.find("GuiUplotMessage", SCOPE), 120)
                await tab.close()
                return built
            built = run_async(scenario())
    finally:
        del os.environ[TOKEN_VARIABLE]
    assert len(command_lines) >= 4 and not any(token.encode() in line for line in command_lines)
    assert built


def test_a_tab_may_change_only_what_a_browser_changes(tmp_path):
    """A control's internal attributes (its callbacks, ``removed``) and an Exercise that does not
    exist are refused with one line in the tab and one in the log; the controls keep working."""
    port = 8468
    log = tmp_path / "server.log"
    with lab_process(port, data_dir=tmp_path, log=log):
        async def scenario():
            tab = await lab_tab(port)
            slider = tab.find("GuiSliderMessage", NOISE)
            chooser = tab.find("GuiDropdownMessage", "Exercise")
            for updates in ({"update_cb": []}, {"removed": True}, {"value": 1.2, "sync_cb": None}):
                await tab.send({"type": "GuiUpdateMessage", "uuid": slider, "updates": updates})
            for _ in range(3):
                await tab.set_value(chooser, "No such exercise")
            await asyncio.sleep(0.5)
            shown = await tab.wait_for(lambda: _markdown(tab, "could not use"), 20)
            readouts = tab.find_containing("GuiMarkdownMessage", READOUTS)
            before = _markdown(tab, READOUTS)
            await tab.set_value(slider, 1.7)
            answered = await tab.wait_for(lambda: _markdown(tab, READOUTS) != before, 30)
            heading = tab.find_containing("GuiMarkdownMessage", "### Kalman filter")
            await tab.close()
            return shown, bool(readouts) and answered, heading
        shown, answered, heading = run_async(scenario())
    text = log.read_text()
    assert shown and answered and heading, text[-3000:]
    assert text.count("invalid message") == 1 and "Traceback" not in text and "That did not work" not in text


def test_a_dns_rebinding_request_is_refused(tmp_path):
    """A page served as evil.example whose name now points at the lab: Host and Origin both say
    evil.example (they agree), but the lab does not serve that name."""
    import socket

    import viser
    import websockets
    port = 8469
    with lab_process(port, data_dir=tmp_path, log=tmp_path / "server.log"):
        async def scenario():
            sock = socket.create_connection(("127.0.0.1", port))
            connection = await websockets.connect(f"ws://evil.example:{port}", sock=sock,
                                                  subprotocols=[f"viser-v{viser.__version__}"],
                                                  additional_headers={"Origin": f"http://evil.example:{port}"})
            await connection.send(msgspec.msgpack.encode(CAMERA))   # viser opens a tab on its first camera message
            try:
                await asyncio.wait_for(connection.wait_closed(), 60)
            finally:
                await connection.close()
            own = await RawTab().connect(url(port), origin=url(port))
            built = await own.wait_for(lambda: own.find("GuiUplotMessage", SCOPE), 120)
            await own.close()
            return connection.close_code, built
        code, built = run_async(scenario())
    assert code == 1008 and built
