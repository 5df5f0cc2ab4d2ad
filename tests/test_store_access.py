"""Saved experiments (app/infra/store.py) and the access checks (app/infra/access.py)."""

import re
import sqlite3
import threading

import pytest

from app.infra.access import (
    Admission,
    OriginPolicy,
    Throttle,
    check_host,
    check_port,
    client_address,
    is_loopback,
    new_token,
    token_matches,
)
from app.infra.store import CODE_ALPHABET, Store, StoreError, StoreUnavailable, code_prefix, normalise_code
from lab_modules.parameters import ParameterError


def table_count(database, table: str) -> int:
    """Rows of ``table``, read through a connection of its own (either back end)."""
    data_dir, url = database
    if url is None:
        with sqlite3.connect(data_dir / "lab.sqlite3") as db:
            return db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]
    import psycopg
    with psycopg.connect(url) as db:
        return db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]


def test_save_and_load_round_trip(open_test_store, database):
    store = open_test_store()
    code = store.save("kalman_noise", {"gain_factor": 1.5, "feedback": "estimated"}, "run.csv", b"t,x\n1,2\n")
    assert re.fullmatch(rf"KN-[{CODE_ALPHABET}]{{4}}-[{CODE_ALPHABET}]{{4}}-[{CODE_ALPHABET}]{{4}}", code)
    loaded = open_test_store().load(code.lower().replace("-", " "))      # another connection, typed loosely
    assert (loaded.exercise, loaded.kind) == ("kalman_noise", "saved")
    assert loaded.parameters == {"gain_factor": 1.5, "feedback": "estimated"}
    assert (loaded.recording_name, loaded.recording) == ("run.csv", b"t,x\n1,2\n")
    assert store.check() == "ok"
    if database[1] is None:
        assert sqlite3.connect(store.path).execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_autosave_overwrites_only_its_slot(open_test_store, database):
    store = open_test_store()
    slot = store.new_autosave("maglev_tuning", {"seed": 1})
    saved = store.save("maglev_tuning", {"seed": 1})
    store.autosave(slot, "kalman_noise", {"seed": 2}, "a.csv", b"abc")
    assert store.load(slot).parameters == {"seed": 2} and store.load(slot).exercise == "kalman_noise"
    with pytest.raises(StoreError):
        store.autosave(saved, "kalman_noise", {"seed": 3})
    assert store.load(saved).parameters == {"seed": 1}
    store.autosave(slot, "kalman_noise", {"seed": 2}, "a.csv", b"abc")   # same recording stored once
    assert table_count(database, "recordings") == 1


def test_codes_are_checked(open_test_store):
    store = open_test_store()
    for bad in ("", "KN", "KN-0000", "K1-ABCD", "KN-ABCDE", "<b>x</b>", "KN-ABCD-EFGH", "ΚΝ-ABCD"):
        with pytest.raises(StoreError, match="not an experiment code"):
            normalise_code(bad)
    with pytest.raises(StoreError, match="codes never contain 0 "):   # the shape is right: the character is named
        normalise_code("ZZ-0000")
    with pytest.raises(StoreError, match="codes never contain I, O "):
        normalise_code("kn-oi23")
    with pytest.raises(StoreError, match="no experiment is saved under KN-ABCD"):
        store.load("kn-abcd")
    assert code_prefix("lqg_vs_pid") == "LP" and code_prefix("kalman_noise") == "KN"


def test_concurrent_writers_get_distinct_codes(open_test_store):
    stores = [open_test_store() for _ in range(4)]
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
    policy = OriginPolicy(["https://lab.example.org"], served_host="10.0.0.5")    # the lab serves 10.0.0.5
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


# -- a database that fails: full, damaged, another program's ------------------------------------
class FullStore(Store):
    """A store whose file cannot grow past its size when opened (``PRAGMA max_page_count``),
    until ``make_room``: a full disk without filling one."""

    def _open(self):
        db = super()._open()
        pages = db.execute("PRAGMA page_count").fetchone()[0]
        db.execute(f"PRAGMA max_page_count={pages}")
        return db

    def make_room(self) -> None:
        self._db.execute("PRAGMA max_page_count=1000000")


def damaged_database(tmp_path):
    """A lab database with experiments in it whose pages past the first (the schema) are overwritten."""
    store = Store(tmp_path)
    codes = [store.save("kalman_noise", {"seed": i}, "r.csv", bytes([i]) * 5000) for i in range(20)]
    store.close()
    with sqlite3.connect(tmp_path / "lab.sqlite3") as db:
        db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    path = tmp_path / "lab.sqlite3"
    raw = bytearray(path.read_bytes())
    for start in range(4096 * 3, len(raw), 4096):            # keep the header and the schema's pages
        raw[start:start + 200] = b"\xa5" * 200
    path.write_bytes(bytes(raw))
    return codes


def test_a_full_database_is_one_line_and_works_again_with_room(tmp_path, capsys):
    store = FullStore(tmp_path, log_failures=True)
    for attempt in range(3):                                  # logged once, however often it is tried
        with pytest.raises(StoreUnavailable, match="^the disk holding the saved experiments is full$"):
            store.save("kalman_noise", {"seed": attempt}, "big.csv", b"x" * 200_000)
    assert capsys.readouterr().err.count("saved experiments: the disk holding") == 1
    assert store.count() == 0 and store.check() == "ok"       # nothing half written; reading still works
    store.make_room()
    code = store.save("kalman_noise", {"seed": 1}, "big.csv", b"x" * 200_000)
    assert store.load(code).recording == b"x" * 200_000
    assert "works again" in capsys.readouterr().err


def test_a_damaged_database_is_one_line(tmp_path):
    codes = damaged_database(tmp_path)
    store = Store(tmp_path)                                   # the schema is readable: it opens
    failures = []
    for code in codes:
        try:
            store.load(code)
        except StoreUnavailable as error:
            failures.append(str(error))
    with pytest.raises(StoreUnavailable) as saving:
        for i in range(20):
            store.save("kalman_noise", {"seed": i}, "s.csv", bytes([100 + i]) * 5000)
    assert failures and all(f.startswith("the saved-experiments database is damaged") for f in failures)
    assert "damaged" in str(saving.value) and "\n" not in str(saving.value)


def test_a_foreign_database_is_refused_when_opened(tmp_path):
    with sqlite3.connect(tmp_path / "lab.sqlite3") as db:
        db.execute("CREATE TABLE experiments (id INTEGER PRIMARY KEY, name TEXT)")
    with pytest.raises(StoreUnavailable, match="is not the lab's: its table 'experiments' has another layout"):
        Store(tmp_path)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "lab.sqlite3").write_bytes(b"not a database at all " * 500)
    with pytest.raises(StoreUnavailable, match="damaged"):
        Store(tmp_path / "other")


def test_admission_lets_tabs_in_first_come_first_served():
    admission = Admission(limit=2)
    assert admission.try_enter("a") and admission.try_enter("b") and not admission.try_enter("c")
    entered, closed = [], {"e": False}

    def wait(holder):
        if admission.wait_to_enter(holder, lambda: closed.get(holder, False)):
            entered.append(holder)
    waiting = []
    for holder in ("c", "d", "e"):
        waiting.append(threading.Thread(target=wait, args=(holder,)))
        waiting[-1].start()
        while len(admission.line) < len(waiting):      # in line in this order
            threading.Event().wait(0.01)
    closed["e"] = True
    admission.leave("e")                               # a waiting tab that closes leaves the line
    waiting[2].join(10)
    admission.leave("a")
    waiting[0].join(10)
    assert entered == ["c"] and not admission.try_enter("x")      # d waits first: x may not jump the line
    admission.leave("b")
    waiting[1].join(10)
    assert entered == ["c", "d"] and admission.holders == {"c", "d"} and not admission.line


def test_throttle_counts_failed_tries_per_address(monkeypatch, capsys):
    from app.infra import access
    now = [100.0]
    monkeypatch.setattr(access.time, "monotonic", lambda: now[0])
    throttle = Throttle("class token", burst=3, per_minute=6)
    for _ in range(3):
        assert throttle.wait_s("10.0.0.5") == 0
        throttle.failed("10.0.0.5")
    assert throttle.wait_s("10.0.0.5") == pytest.approx(10.0)        # one try every 10 s from now on
    assert throttle.wait_s("10.0.0.6") == 0                          # another address is not held up
    now[0] += 10.0
    assert throttle.wait_s("10.0.0.5") == 0
    throttle.failed("10.0.0.5")
    throttle.failed("10.0.0.5")
    assert capsys.readouterr().err.count("too many failed tries from 10.0.0.5") == 1


def test_client_address_believes_only_trusted_proxies():
    assert client_address("127.0.0.1", "203.0.113.9", frozenset()) == "203.0.113.9"   # the hall's HAProxy
    assert client_address("127.0.0.1", "1.1.1.1, 203.0.113.9", frozenset()) == "203.0.113.9"   # the proxy's own
    assert client_address("203.0.113.9", "1.1.1.1", frozenset()) == "203.0.113.9"     # a client's claim
    assert client_address("10.0.0.2", "203.0.113.9", frozenset({"10.0.0.2"})) == "203.0.113.9"
    assert client_address(None, None, frozenset()) == "unknown"


def test_class_tokens_come_from_flag_file_or_environment(tmp_path):
    from app.infra.access import TOKEN_VARIABLE, chosen_token, token_bits
    path = tmp_path / "token.txt"
    path.write_text("  Strong-Token-4711\nsecond line\n")
    assert chosen_token("given1", str(path), {TOKEN_VARIABLE: "envtoken"}) == ("given1", "from --token")
    assert chosen_token(None, str(path), {TOKEN_VARIABLE: "envtoken"}) == ("Strong-Token-4711", "from --token-file")
    assert chosen_token(None, None, {TOKEN_VARIABLE: "envtoken"}) == ("envtoken", f"from {TOKEN_VARIABLE}")
    assert chosen_token(None, None, {}) == (None, "")
    with pytest.raises(ParameterError, match="--token-file .*No such file"):
        chosen_token(None, str(tmp_path / "missing"), {})
    with pytest.raises(ParameterError, match=TOKEN_VARIABLE):
        chosen_token(None, None, {TOKEN_VARIABLE: "a b"})
    generated = new_token()
    assert re.fullmatch(r"[a-z2-9]{4}-[a-z2-9]{4}-[a-z2-9]{4}", generated) and token_bits(generated) > 59
    assert token_matches(generated, generated.replace("-", " ").upper()) and token_bits("kalman42") < 50



@pytest.mark.parametrize("host, given, expected", [("0.0.0.0", None, "generated"), ("127.0.0.1", None, None),
                                                   ("0.0.0.0", "kalman42", "from --token")])
def test_a_token_is_generated_off_loopback_and_a_weak_one_is_warned_of(monkeypatch, host, given, expected):
    """Off loopback with no token given the server makes one (never an open lab); a chosen token
    short enough to guess gets a warning, and --token the note that the process list shows it."""
    import argparse

    from app.infra.access import TOKEN_VARIABLE
    from app.server import Settings
    monkeypatch.delenv(TOKEN_VARIABLE, raising=False)
    args = argparse.Namespace(host=host, port=8080, exercise="kalman_noise", data_dir=None, token=given,
                              token_file=None, allow_origin=[], max_tabs="60", trusted_proxy=[], database=None,
                              instructor_token_file=None)
    settings = Settings.from_args(args)
    assert settings.token_source == (expected or "")
    lines = " ".join(settings.token_lines())
    if expected is None:
        assert settings.token is None and lines == ""
    elif expected == "generated":
        assert re.fullmatch(r"[a-z2-9]{4}-[a-z2-9]{4}-[a-z2-9]{4}", settings.token)
        assert "generated" in lines and "warning" not in lines
    else:
        assert settings.token == "kalman42" and "can be guessed" in lines and "process list" in lines

def test_old_short_codes_keep_opening(tmp_path):
    """Codes made before the longer ones (two letters and four characters) open as before."""
    store = Store(tmp_path)
    with sqlite3.connect(store.path) as db:
        db.execute("INSERT INTO experiments VALUES ('KN-7Q3M', 'saved', 'kalman_noise', '{\"seed\": 4}', NULL, "
                   "NULL, 0, 0)")
    assert store.load("kn 7q3m").parameters == {"seed": 4} and normalise_code("KN7Q3M") == "KN-7Q3M"
    assert normalise_code("kn7q3mx9tahprw") == "KN-7Q3M-X9TA-HPRW"


def test_host_must_be_a_name_the_lab_serves():
    """DNS rebinding: a page at evil.example whose name was re-pointed at the lab sends Host and
    Origin evil.example; both agree, but the lab does not serve that name."""
    import socket
    policy = OriginPolicy(["https://lab.example.org"], served_host="0.0.0.0")
    assert not policy.permits("http://evil.example:8080", "evil.example:8080")
    assert not policy.permits("http://10.255.255.7:8080", "10.255.255.7:8080")   # not this machine
    for host in ("127.0.0.1", "localhost", "[::1]", socket.gethostname()):
        assert policy.permits(f"http://{host}:8080", f"{host}:8080"), host
    assert policy.permits("https://lab.example.org", "lab.example.org")           # allowed explicitly
    named = OriginPolicy([], served_host="lab.school.example")
    assert named.permits("http://lab.school.example:8080", "lab.school.example:8080")
    assert not named.serves("other.example") and not named.serves("[bad")
