"""The worksheet's paper-vs-lab table is rendered from the exercise's claims: it
appears at once with "…" and fills in with the live lab values without the tab
waiting for them."""

from __future__ import annotations

from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only


def test_worksheet_claims_table_fills_in(open_tab):
    tab = open_tab()
    page = tab.page
    page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
    tab.open_panel_tab("Worksheet")
    table = page.locator("table").filter(has_text="accepted").first
    table.wait_for(timeout=10000)
    claims = get("kalman_noise").claims
    assert table.locator("tbody tr").count() == len(claims)
    # measured in the background (niced process): every status cell becomes pass or deviation
    page.wait_for_function(
        """() => { const t = [...document.querySelectorAll('table')].find(e => e.innerText.includes('accepted'));
                   return t && [...t.querySelectorAll('tbody tr')].every(
                       r => /pass|deviation/.test(r.lastElementChild.innerText)); }""", timeout=120000)
    assert claims[0].paper in table.inner_text()
    assert not tab.errors, tab.errors
