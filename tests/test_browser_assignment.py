"""An assignment in a real browser: a student opens the link (the page's script reports the
query the websocket does not carry), gives their id, finds the fixed controls greyed, changes a
control, submits and reads each spec's result; the instructor opens the page with the instructor
token, sees the submission and downloads the gradebook."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import pytest

from app.commands.browser_bench import free_port
from app.infra import coursework
from app.infra.database import open_store
from lab_modules.evaluation import assignments
from tests.conftest import Tab, browser_only
from tests.wsclient import lab_process

pytestmark = browser_only
INSTRUCTOR_TOKEN = "prof-7kq2-x9ma"
SHOTS = os.environ.get("LAB_SCREENSHOTS")      # a folder to keep the screenshots in (to look at them)


def _shot(page, name: str) -> None:
    if SHOTS:
        page.screenshot(path=os.path.join(SHOTS, f"assignment_{name}.png"))


@pytest.fixture
def assignment_lab(tmp_path):
    """A lab with one assignment and an instructor token: (url, code)."""
    from app.cli import main
    token_file = tmp_path / "instructor-token.txt"
    token_file.write_text(INSTRUCTOR_TOKEN)
    argv = ["assignment", "create", "--exercise", "kalman_noise", "--title", "Filter the sensor noise",
            "--vary", "sensor_noise_um=1.0..1.6", "--vary", "current_noise_a=1.5..2.2", "--lock", "sensor_lag_us",
            "--spec", "current_noise_reduction_percent>=75:2", "--spec", "max_gain_factor_estimated>=3:2",
            "--duration", "0.5", "--data-dir", str(tmp_path), "--json"]
    import contextlib
    import json
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(argv) == 0
    code = json.loads(out.getvalue())["code"]
    port = free_port()
    with lab_process(port, "--instructor-token-file", str(token_file), data_dir=tmp_path,
                     log=tmp_path / "server.log"):
        yield f"http://127.0.0.1:{port}", code, tmp_path


def test_a_student_submits_from_the_link_and_the_instructor_exports(browser, assignment_lab):
    url, code, data_dir = assignment_lab
    student = Tab(browser, f"{url}/?assignment={code}")
    page = student.page
    page.get_by_text("Name or student id", exact=True).wait_for(timeout=120000)
    student.entry_box("Name or student id").fill("s5001")
    page.get_by_role("button", name="Start the assignment").click()
    page.get_by_role("button", name="Submit").wait_for(timeout=60000)
    assert student.entry_box("Position sensor noise σ [µm]").is_disabled()
    assert student.entry_box("Sensor lag T_mx [µs]").is_disabled()
    assert not student.entry_box("Common gain factor [×]").is_disabled()
    page.get_by_label("Feedback source", exact=True).first.click()
    page.get_by_role("option", name="estimated", exact=True).click()
    page.wait_for_timeout(1500)
    _shot(page, "student_before")
    page.get_by_role("button", name="Submit").click()
    page.get_by_text("Score 4/4").wait_for(timeout=60000)
    assert page.get_by_text("✓ pass").count() == 2
    _shot(page, "student_results")

    teacher = Tab(browser, f"{url}/?instructor={code}")
    tpage = teacher.page
    tpage.get_by_text("Instructor token", exact=True).wait_for(timeout=120000)
    teacher.entry_box("Instructor token").fill(INSTRUCTOR_TOKEN)
    tpage.get_by_role("button", name="Open the instructor page").click()
    tpage.get_by_role("cell", name="s5001", exact=True).wait_for(timeout=60000)
    _shot(tpage, "instructor")
    _shot(tpage, "before_export")
    tpage.wait_for_timeout(100)
    with tpage.expect_download() as download:
        tpage.get_by_role("button", name="Canvas").click()
    _shot(tpage, "after_export")
    rows = list(csv.reader(io.StringIO(Path(download.value.path()).read_text(encoding="utf-8"))))
    assert rows[0][-1] == f"Filter the sensor noise ({code})" and ["s5001", "", "s5001", "", "", "4"] in rows
    tpage.get_by_role("button", name="Open as a lab tab").click()
    link = tpage.get_by_role("link", name="in a new tab")
    link.wait_for(timeout=30000)
    assert link.get_attribute("target") == "_blank"
    opened = Tab(browser, f"{url}/{link.get_attribute('href')}")      # what the link opens, in a tab of its own
    opened.page.get_by_text("Opened", exact=False).wait_for(state="attached", timeout=120000)
    _shot(opened.page, "submission_opened")
    _, assignment = coursework.load(open_store(None, data_dir), code)
    drawn = assignments.variant(assignment, code, "s5001")
    assert float(opened.entry_box("Position sensor noise σ [µm]").input_value()) == drawn["sensor_noise_um"]
    assert not [e for e in student.errors + teacher.errors if "favicon" not in e]
    for tab_page in (page, tpage, opened.page):
        tab_page.close()
