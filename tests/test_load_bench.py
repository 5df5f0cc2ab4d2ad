"""The load bench's verdict on a stalled tab (``load_bench.Tab.stall``), from arrival times alone."""

import pytest
import websockets
from websockets.frames import Close

from app.commands.load_bench import Tab, _closing, held_in_every_run


def _tab(scope_times: list[float], frame_times: list[float] | None = None) -> Tab:
    tab = Tab("ws://unused", ("Rotor position [µm]",))
    tab.scope_times = scope_times
    tab.frame_times = sorted(scope_times + (frame_times or []))
    return tab


def test_a_tab_streaming_through_the_window_did_not_stall():
    assert _tab([0.04 * k for k in range(250)]).stall(0.0, 10.0) is None


def test_a_silent_connection_stalled_until_the_end():
    assert _tab([0.5, 1.0, 1.5]).stall(0.0, 10.0) == "no message at all for 8.5 s until the end of the window"


def test_a_connection_silent_since_before_the_window_tells_what_came_before():
    tab = _tab([0.04 * k for k in range(1, 488)], frame_times=[19.6])
    assert tab.stall(30.0, 38.0) == ("no message at all for 8.0 s until the end of the window; before the window "
                                     "487 scope updates, the last 10.5 s before it, the last message 10.4 s before it")
    assert _tab([], frame_times=[1.0, 2.0]).stall(30.0, 38.0) == \
        "no message at all for 8.0 s until the end of the window; no scope update since it opened (2 frames in all)"


def test_a_slow_server_stalled_and_streamed_again():
    assert _tab([1.0, 4.0, 4.5, 5.0, 9.8]).stall(0.0, 10.0) == "no message at all for 4.8 s"


def test_other_messages_without_scope_updates_are_told_apart():
    assert _tab([1.0], frame_times=[2.0, 3.0]).stall(0.0, 4.0) == \
        "messages but no scope update for 3.0 s until the end of the window (2 frames)"


def test_a_tab_that_ended_in_the_window_stalled_with_its_reason():
    tab = _tab([0.04 * k for k in range(100)])
    tab.closed, tab.ended_at = "closed by server with code 1008 (origin not allowed)", 4.0
    assert tab.stall(0.0, 10.0) == tab.closed
    assert tab.stall(0.0, 3.9) is None                       # it ended after that window


@pytest.mark.parametrize(("received", "why"), [
    (Close(1011, "internal error"), "closed by server with code 1011 (internal error)"),
    (Close(1000, ""), "closed by server with code 1000"),
    (None, "connection lost without a close frame"),
])
def test_why_a_connection_ended(received, why):
    assert _closing(websockets.ConnectionClosed(received, None)) == why


def test_a_tab_on_another_panel_is_judged_by_its_messages():
    """Its Scope is hidden, so it gets no scope updates: its readouts and status every second keep it alive."""
    away = _tab([], frame_times=[float(k) for k in range(10)])
    away.panel = "Pole map"
    assert not away.watches_scope and away.stall(0.0, 10.0) is None
    silent = _tab([], frame_times=[1.0, 2.0])
    silent.panel = "Analysis"
    assert silent.stall(0.0, 10.0) == "no message at all for 8.0 s until the end of the window"


def test_a_step_holds_in_the_runs_where_it_was_ok():
    runs = [{"steps": [{"clients": 25, "ok": True}, {"clients": 50, "ok": False}]},
            {"steps": [{"clients": 25, "ok": True}, {"clients": 50, "ok": True}]}]
    assert held_in_every_run(runs) == {25: 2, 50: 1}
