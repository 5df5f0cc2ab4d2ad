"""Saved experiments (app/infra/store.py) and the access checks (app/infra/access.py)."""

import sqlite3
import threading

import pytest

from app.infra.access import OriginPolicy, check_host, check_port, is_loopback, new_token, token_matches
from app.infra.store import CODE_ALPHABET, Store, StoreError, code_prefix, normalise_code
from lab_modules.parameters import ParameterError


def test_save_and_load_round_trip(tmp_path):
    store = Store(tmp_path)
    code = store.save("kalman_noise", {"gain_factor": 1.5, "feedback": "estimated"}, "run.csv", b"t,x\n1,2\n")
    assert code.startswith("KN-") and len(code) == 7 and all(c in CODE_ALPHABET for c in code[3:])
    loaded = Store(tmp_path).load(code.lower().replace("-", " "))      # another connection, typed loosely
    assert (loaded.exercise, loaded.kind) == ("kalman_noise", "saved")
    assert loaded.parameters == {"gain_factor": 1.5, "feedback": "estimated"}
    assert (loaded.recording_name, loaded.recording) == ("run.csv", b"t,x\n1,2\n")
    assert store.check() == "ok"
    assert sqlite3.connect(store.path).execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_autosave_overwrites_only_its_slot(tmp_path):
    store = Store(tmp_path)
    slot = store.new_autosave("maglev_tuning", {"seed": 1})
    saved = store.save("maglev_tuning", {"seed": 1})
    store.autosave(slot, "kalman_noise", {"seed": 2}, "a.csv", b"abc")
    assert store.load(slot).parameters == {"seed": 2} and store.load(slot).exercise == "kalman_noise"
    with pytest.raises(StoreError):
        store.autosave(saved, "kalman_noise", {"seed": 3})
    assert store.load(saved).parameters == {"seed": 1}
    store.autosave(slot, "kalman_noise", {"seed": 2}, "a.csv", b"abc")   # same recording stored once
    assert sqlite3.connect(store.path).execute("SELECT COUNT(*) FROM recordings").fetchone()[0] == 1


def test_codes_are_checked(tmp_path):
    store = Store(tmp_path)
    for bad in ("", "KN", "KN-0000", "K1-ABCD", "KN-ABCDE", "<b>x</b>"):
        with pytest.raises(StoreError, match="not an experiment code"):
            normalise_code(bad)
    with pytest.raises(StoreError, match="codes never contain 0 "):   # the shape is right: the character is named
        normalise_code("ZZ-0000")
    with pytest.raises(StoreError, match="codes never contain I, O "):
        normalise_code("kn-oi23")
    with pytest.raises(StoreError, match="no experiment is saved under KN-ABCD"):
        store.load("kn-abcd")
    assert code_prefix("lqg_vs_pid") == "LP" and code_prefix("kalman_noise") == "KN"


def test_concurrent_writers_get_distinct_codes(tmp_path):
    stores = [Store(tmp_path) for _ in range(4)]
    codes: list[str] = []

    def writer(store):
        for i in range(25):
            codes.append(store.save("kalman_noise", {"seed": i}))
    threads = [threading.Thread(target=writer, args=(s,)) for s in stores]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(codes)) == 100 and stores[0].count() == 100


def test_port_and_host_checks():
    assert check_port("8080") == 8080
    for bad, words in (("99999", "out of range"), ("-5", "out of range"), ("0", "out of range"),
                       ("http", "not a whole number")):
        with pytest.raises(ParameterError, match=words):
            check_port(bad)
    assert check_host("0.0.0.0") == "0.0.0.0" and check_host("::1") == "::1"
    for bad in ("256.1.1.1", "1.2.3", ""):
        with pytest.raises(ParameterError):
            check_host(bad)
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("0.0.0.0")


def test_token_and_origin():
    token = new_token()
    assert token_matches(token, f"  {token.upper()} ") and not token_matches(token, token + "x")
    assert not token_matches(token, None)
    policy = OriginPolicy(["https://lab.example.org"])
    assert policy.permits("http://10.0.0.5:8080", "10.0.0.5:8080")
    assert policy.permits("https://lab.example.org", "10.0.0.5:8080")
    assert policy.permits(None, "10.0.0.5:8080")                     # not a browser: the token decides
    assert not policy.permits("http://evil.example", "10.0.0.5:8080")
    assert not policy.permits("http://10.0.0.5:8081", "10.0.0.5:8080")
    assert not policy.permits("null", "10.0.0.5:8080")
    with pytest.raises(ParameterError):
        OriginPolicy(["not an origin"])

OPEN_FRESH = """
import sys, time
from app.infra.store import Store
time.sleep(max(0.0, float(sys.argv[2]) - time.time()))    # all processes open at the same instant
Store(sys.argv[1]).save("kalman_noise", {})
"""


@pytest.mark.parametrize("round_", range(3))
def test_processes_opening_a_fresh_database_at_once(tmp_path, round_):
    """Lab processes started together (``serve --workers``) all open a new database: switching it
    to WAL takes an exclusive lock that SQLite does not wait for, so none may fail on it."""
    import subprocess
    import sys
    import time
    start = time.time() + 1.5
    processes = [subprocess.Popen([sys.executable, "-c", OPEN_FRESH, str(tmp_path), str(start)],
                                  stderr=subprocess.PIPE, text=True) for _ in range(6)]
    errors = [p.communicate(timeout=60)[1] for p in processes]
    assert [p.returncode for p in processes] == [0] * 6, errors
    assert Store(tmp_path).count() == 6
