"""A reloaded tab gets its autosaved experiment back (issue 12): the browser keeps the tab's
autosave code (localStorage), and a new page in that browser restores it."""

from __future__ import annotations

import time

from app.infra.store import Store, StoreError
from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only
READOUT = "RMS displacement, measured feedback"
NOISE = "Position sensor noise σ [µm]"


def _wait_autosaved(tab, lab_server, exercise: str, noise: float | None = None, timeout_s: float = 60.0) -> str:
    """Wait until the code the browser keeps names an autosave of ``exercise`` (at ``noise``)."""
    store = Store(lab_server[1].parent / "lab-data")
    deadline = time.perf_counter() + timeout_s
    while time.perf_counter() < deadline:
        code = tab.page.evaluate("localStorage.getItem('viser-user:autosave')")
        try:
            saved = store.load(code) if code else None
        except StoreError:
            saved = None
        if saved is not None and saved.exercise == exercise and (
                noise is None or saved.parameters.get("sensor_noise_um") == noise):
            return code
        time.sleep(0.2)
    raise AssertionError(f"no autosave of {exercise} kept in the browser after {timeout_s:.0f} s")


def test_reload_restores_the_autosaved_experiment(open_tab, lab_server):
    tab = open_tab()
    tab.page.get_by_text(READOUT).first.wait_for(timeout=60000)
    tab.set_number(NOISE, "3")
    first = _wait_autosaved(tab, lab_server, "kalman_noise", 3.0)
    tab.page.reload()
    tab.page.get_by_text(READOUT).first.wait_for(timeout=60000)
    tab.page.get_by_text(f"Restored {first}").first.wait_for(state="attached", timeout=10000)
    assert "3" in tab.visible_input_values(), tab.visible_input_values()

    other = get("thrust_liftoff")                   # the exercise comes back too
    tab.switch_exercise(other.title)
    _wait_autosaved(tab, lab_server, other.name)
    tab.page.reload()
    tab.page.get_by_role("heading", name=other.title, exact=True).wait_for(timeout=60000)
    assert not tab.errors, tab.errors
