"""Assignments in the served lab (raw websocket tabs, loopback only): a student joins from the
link, gets their own plant with the fixed controls disabled, submits and sees the results graded
on the server; the instructor page behind its own token; what one student cannot do to another;
a burst of submissions against another tab.  The page's query string reaches the server through
the hidden "Page query" box (``app/panels/page_query.py``), which the tests fill as the page's
script would.  Figures are printed (``pytest -s``)."""

from __future__ import annotations

import asyncio
import csv
import io
import statistics
import time
from pathlib import Path

import pytest

from app.cli import main
from app.infra import coursework
from app.infra.database import open_store
from app.panels.assignment import FAILED, PASSED
from app.panels.text import escaped
from lab_modules.evaluation import assignments
from tests.wsclient import RawTab, lab_process, run_async

pytestmark = pytest.mark.classroom

NOISE = "Position sensor noise σ [µm]"
LAG = "Sensor lag T_mx [µs]"
FEEDBACK = "Feedback source"
READOUTS = "| quantity | value | unit |"
INSTRUCTOR_TOKEN = "prof-7kq2-x9ma"
SPECS = ["current_noise_reduction_percent>=75:2", "max_gain_factor_estimated>=3:2"]


def _create(data_dir: Path, capsys) -> str:
    argv = ["assignment", "create", "--exercise", "kalman_noise", "--title", "Filter the noise", "--vary",
            "sensor_noise_um=1.0..1.6", "--vary", "current_noise_a=1.5..2.2", "--lock", "sensor_lag_us",
            "--duration", "0.5", "--data-dir", str(data_dir)]
    for spec in SPECS:
        argv += ["--spec", spec]
    capsys.readouterr()
    assert main(argv) == 0
    return capsys.readouterr().out.split()[1].rstrip(":")


def _served(tmp_path: Path, port: int):
    token_file = tmp_path / "instructor-token.txt"
    token_file.write_text(INSTRUCTOR_TOKEN + "\n")
    return lab_process(port, "--instructor-token-file", str(token_file), data_dir=tmp_path,
                       log=tmp_path / "server.log")


async def _tab(port: int, keep_messages: bool = False) -> RawTab:
    tab = await RawTab(keep_messages).connect(f"http://127.0.0.1:{port}")
    assert await tab.wait_for(lambda: tab.find_containing("GuiMarkdownMessage", READOUTS), 120)
    return tab


async def _open_link(tab: RawTab, query: str) -> None:
    """What the page's script does for a link ``http://lab/?...``."""
    box = await tab.wait_for(lambda: tab.find("GuiTextMessage", "Page query"), 30)
    await tab.set_value(box, query)


async def _join(tab: RawTab, code: str, student: str) -> str:
    """Open the assignment link and give ``student``; the Submit button's uuid."""
    await _open_link(tab, f"?assignment={code}")
    who = await tab.wait_for(lambda: tab.find("GuiTextMessage", "Name or student id"), 30)
    await tab.set_value(who, student)
    await tab.set_value(tab.find("GuiButtonMessage", "Start the assignment"), True)
    submit = await tab.wait_for(lambda: tab.find("GuiButtonMessage", "Submit"), 60)
    assert submit
    assert await tab.wait_for(lambda: tab.find_containing("GuiMarkdownMessage", READOUTS), 60)
    return submit


def _results(tab: RawTab) -> str | None:
    found = tab.find_containing("GuiMarkdownMessage", "**Score")
    return tab.elements[found]["content"] if found else None


def _disabled(tab: RawTab, label: str) -> tuple[bool, str]:
    """(disabled, hint) of the control labelled ``label``, with the updates since it was made."""
    uuid = tab.find("GuiSliderMessage", label)
    props = dict(tab.elements[uuid]["props"])
    for _, updated, changes in tab.updates:
        if updated == uuid:
            props.update(changes)
    return props.get("disabled", False), props.get("hint") or ""


def test_a_student_joins_from_the_link_and_is_graded_on_the_server(tmp_path, capsys):
    code = _create(tmp_path, capsys)
    port = 8941
    with _served(tmp_path, port):
        async def scenario():
            tab = await _tab(port)
            submit = await _join(tab, code, "s1001")
            drawn = assignments.variant(coursework.load(open_store(None, tmp_path), code)[1], code, "s1001")
            noise = tab.find("GuiSliderMessage", NOISE)
            fixed = {label: _disabled(tab, label) for label in (NOISE, LAG)}
            free = _disabled(tab, "Common gain factor [×]")
            await tab.set_value(noise, 1.0)                  # a fixed control: refused by the server
            refused = await tab.wait_for(
                lambda: tab.find_containing("GuiMarkdownMessage", "a change of a control that is fixed"), 30)
            await tab.set_value(tab.find("GuiDropdownMessage", FEEDBACK), "estimated")
            await asyncio.sleep(1.5)
            await tab.set_value(submit, True)
            shown = await tab.wait_for(lambda: _results(tab), 60)
            await tab.close()
            return drawn, tab.elements[noise]["value"], fixed, free, shown, refused
        drawn, slider_value, fixed, free, shown, refused = run_async(scenario())
    store = open_store(None, tmp_path)
    _, assignment = coursework.load(store, code)
    [submission] = store.submissions(code, "s1001")
    print(f"\nstudent s1001 on {drawn}: {shown}")
    assert slider_value == drawn["sensor_noise_um"]
    assert all(disabled for disabled, _ in fixed.values()) and not free[0]
    assert "drawn for you" in fixed[NOISE][1] and "Fixed by your instructor" in fixed[LAG][1]
    assert refused, "the fixed slider's update was not refused"
    assert submission.parameters["feedback"] == "estimated"
    assert "sensor_noise_um" not in submission.parameters and "sensor_lag_us" not in submission.parameters
    _, regraded = assignments.grade_submission(assignment, code, "s1001", submission.parameters)
    assert [r.passed for r in regraded] == [r["passed"] for r in submission.results]
    assert submission.score == assignments.score(regraded)
    for result in regraded:
        assert f"| {escaped(result.metric)} " in shown and (PASSED if result.passed else FAILED) in shown
    assert f"**Score {submission.score:g}/4**" in shown


def _csv_download(tab: RawTab) -> str:
    """The newest file the server sent to ``tab`` (its parts joined)."""
    start = [m for m in tab.messages if m["type"] == "FileTransferStartDownload"][-1]
    parts = sorted((m for m in tab.messages if m["type"] == "FileTransferPart"
                    and m["transfer_uuid"] == start["transfer_uuid"]), key=lambda m: m["part_index"])
    return b"".join(bytes(m["content"]) for m in parts).decode()


def test_the_instructor_page_needs_its_own_token_sees_the_class_and_exports(tmp_path, capsys):
    code = _create(tmp_path, capsys)
    port = 8942
    with _served(tmp_path, port):
        async def scenario():
            student = await _tab(port, keep_messages=True)
            submit = await _join(student, code, "s2002")
            await student.set_value(student.find("GuiDropdownMessage", FEEDBACK), "estimated")
            await asyncio.sleep(1.5)
            await student.set_value(submit, True)
            assert await student.wait_for(lambda: _results(student), 60)
            teacher = await _tab(port, keep_messages=True)
            await _open_link(teacher, f"?instructor={code}")
            token = await teacher.wait_for(lambda: teacher.find("GuiTextMessage", "Instructor token"), 30)
            button = teacher.find("GuiButtonMessage", "Open the instructor page")
            await teacher.set_value(token, "not-the-token")
            await teacher.set_value(button, True)
            wrong = await teacher.wait_for(
                lambda: teacher.find_containing("GuiMarkdownMessage", "not the instructor token"), 30)
            await teacher.set_value(token, INSTRUCTOR_TOKEN)
            await teacher.set_value(button, True)
            table = await teacher.wait_for(lambda: teacher.find_containing("GuiMarkdownMessage", "| student |"), 60)
            first = teacher.elements[table]["content"]
            newcomer = await _tab(port)                       # a second student: the page follows by itself
            await _join(newcomer, code, "s2003")
            followed = await teacher.wait_for(lambda: "s2003" in (teacher.elements[table]["content"] or ""), 30)
            exports = teacher.find("GuiButtonGroupMessage", "Gradebook (CSV)")
            await teacher.set_value(exports, "Canvas")
            assert await teacher.wait_for(lambda: teacher.find_containing("GuiMarkdownMessage", "Sent the Canvas"), 30)
            gradebook = _csv_download(teacher)
            await teacher.set_value(teacher.find("GuiButtonMessage", "Open as a lab tab"), True)
            link = await teacher.wait_for(lambda: teacher.find_containing("GuiMarkdownMessage", "?experiment="), 30)
            link_text = teacher.elements[link]["content"]
            for tab in (student, teacher, newcomer):
                await tab.close()
            return wrong, first, followed, gradebook, link_text, repr(student.messages), repr(teacher.messages)
        wrong, first, followed, gradebook, link_text, student_saw, teacher_saw = run_async(scenario())
    store = open_store(None, tmp_path)
    _, assignment = coursework.load(store, code)
    [submission] = store.submissions(code, "s2002")
    print(f"\ninstructor page:\n{first}\n\n{gradebook}\n{link_text}")
    assert wrong and followed
    drawn = assignments.variant(assignment, code, "s2002")
    assert "s2002" in first and f"{drawn['sensor_noise_um']:g}" in first
    rows = list(csv.reader(io.StringIO(gradebook)))
    assert rows[0][-1] == f"Filter the noise ({code})" and rows[1][-1] == "4"
    assert ["s2002", "", "s2002", "", "", f"{submission.score:g}"] in rows
    assert ["s2003", "", "s2003", "", "", ""] in rows            # opened, nothing submitted: empty cell
    opened = store.load(link_text.split("?experiment=")[1].split('"')[0])
    assert opened.exercise == "kalman_noise" and opened.parameters["feedback"] == "estimated"
    assert opened.parameters["sensor_noise_um"] == drawn["sensor_noise_um"]
    assert INSTRUCTOR_TOKEN not in student_saw and INSTRUCTOR_TOKEN not in teacher_saw


def test_the_instructor_creates_an_assignment_in_the_page(tmp_path):
    """``?instructor`` without a code: the form refuses a bad line in one line naming its field and
    creates what the command line would, with the student link."""
    port = 8944
    with _served(tmp_path, port):
        async def scenario():
            teacher = await _tab(port)
            await _open_link(teacher, "?instructor")
            token = await teacher.wait_for(lambda: teacher.find("GuiTextMessage", "Instructor token"), 30)
            await teacher.set_value(token, INSTRUCTOR_TOKEN)
            await teacher.set_value(teacher.find("GuiButtonMessage", "Open the instructor page"), True)
            about = await teacher.wait_for(lambda: teacher.find_containing("GuiMarkdownMessage", "Metrics a spec"), 60)
            fields = {label: teacher.find("GuiTextMessage", label)
                      for label in ("Title", "Drawn per student", "Locked", "Specs", "Deadline")}
            await teacher.set_value(fields["Title"], "Filter the noise")
            await teacher.set_value(fields["Drawn per student"], "sensor_noise_um=1.0..1.6\ncurrent_noise_a=2.2..1.5")
            await teacher.set_value(fields["Locked"], "sensor_lag_us")
            await teacher.set_value(fields["Specs"], "\n".join(SPECS))
            create = teacher.find("GuiButtonMessage", "Create the assignment")
            await teacher.set_value(create, True)
            refused = await teacher.wait_for(lambda: teacher.find_containing("GuiMarkdownMessage", "⚠️"), 60)
            refusal = teacher.elements[refused]["content"]
            await teacher.set_value(fields["Drawn per student"], "sensor_noise_um=1.0..1.6\ncurrent_noise_a=1.5..2.2")
            await teacher.set_value(create, True)
            assert await teacher.wait_for(lambda: "Created" in (teacher.elements[refused]["content"] or ""), 60)
            created = teacher.elements[refused]["content"]
            await teacher.close()
            return teacher.elements[about]["content"], refusal, created
        about, refusal, created = run_async(scenario())
    print(f"\n{refusal}\n{created}")
    assert "`sensor_noise_um`" in about and "`current_noise_reduction_percent`" in about
    assert refusal.count("\n") == 0 and "Drawn per student:" in refusal and "LOW must be below HIGH" in refusal
    code = created.split("**")[1].replace("\\", "")                  # markdown-escaped hyphens
    assert f"(?assignment={code})" in created and f"?instructor={code}" in created
    _, assignment = coursework.load(open_store(None, tmp_path), code)
    assert assignment.title == "Filter the noise" and assignment.locked == ("sensor_lag_us",)
    assert [(v.parameter, v.low, v.high) for v in assignment.variations] == [
        ("sensor_noise_um", 1.0, 1.6), ("current_noise_a", 1.5, 2.2)]
    assert [(spec.metric, spec.relation, spec.bound, spec.points) for spec in assignment.specs] == [
        ("current_noise_reduction_percent", ">=", 75.0, 2.0), ("max_gain_factor_estimated", ">=", 3.0, 2.0)]


def test_one_student_cannot_see_or_submit_for_another(tmp_path, capsys):
    """Each tab shows only its own student's plant and results; a tab that joined as one student
    cannot submit for another (the id is given once, the dialog is gone); a wrong code opens nothing."""
    code = _create(tmp_path, capsys)
    port = 8943
    with _served(tmp_path, port):
        async def scenario():
            first = await _tab(port)
            submit_first = await _join(first, code, "s3001")
            await first.set_value(submit_first, True)
            first_results = await first.wait_for(lambda: _results(first), 60)
            second = await _tab(port, keep_messages=True)
            await _open_link(second, "?assignment=KN-AAAA-BBBB-CCCC")
            unknown = await second.wait_for(
                lambda: second.find_containing("GuiMarkdownMessage", "did not open"), 30)
            await _open_link(second, "?assignment=")       # the same box again: a new value
            await _open_link(second, f"?assignment={code}")
            who = await second.wait_for(lambda: second.find("GuiTextMessage", "Name or student id"), 30)
            join = second.find("GuiButtonMessage", "Start the assignment")
            submit_second = await _join(second, code, "s3002")
            await second.set_value(who, "s3001")              # the dialog is gone: changes nothing
            await second.set_value(join, True)
            await asyncio.sleep(1.0)
            await second.set_value(submit_second, True)
            assert await second.wait_for(lambda: _results(second), 60)
            noise = second.elements[second.find("GuiSliderMessage", NOISE)]["value"]
            for tab in (first, second):
                await tab.close()
            return first_results, unknown, noise, repr(second.messages)
        first_results, unknown, second_noise, second_saw = run_async(scenario())
    store = open_store(None, tmp_path)
    _, assignment = coursework.load(store, code)
    assert unknown
    assert second_noise == assignments.variant(assignment, code, "s3002")["sensor_noise_um"]
    assert second_noise != assignments.variant(assignment, code, "s3001")["sensor_noise_um"]
    assert "s3001" not in second_saw                        # neither the other's id nor anything of theirs
    assert "Submission 1" in second_saw and "Submission 2" not in second_saw
    assert len(store.submissions(code, "s3001")) == 1 and len(store.submissions(code, "s3002")) == 1
    assert first_results


def test_a_burst_of_submissions_does_not_stall_another_tab(tmp_path, capsys):
    """One student presses Submit 100 times in 2 s: the presses coalesce on that tab's worker,
    whose grading is charged to the tab's CPU budget, and another tab's slider round trip stays
    within a factor of its quiet one."""
    code = _create(tmp_path, capsys)
    port = 8944
    with _served(tmp_path, port):
        async def round_trip(tab, slider, value):
            readouts = tab.find_containing("GuiMarkdownMessage", READOUTS)
            before = tab.elements[readouts]["content"]
            start = time.perf_counter()
            await tab.set_value(slider, value)
            assert await tab.wait_for(lambda: tab.elements[readouts]["content"] != before, 20)
            return (time.perf_counter() - start) * 1e3

        async def scenario():
            other = await _tab(port)
            slider = other.find("GuiSliderMessage", NOISE)
            student = await _tab(port)
            submit = await _join(student, code, "s4001")
            await asyncio.sleep(2)
            quiet = []
            for i in range(6):
                quiet.append(await round_trip(other, slider, 1.0 + 0.1 * (i % 2)))
                await asyncio.sleep(0.3)

            async def burst():
                for _ in range(100):
                    await student.set_value(submit, True)
                    await asyncio.sleep(0.02)
            started = time.perf_counter()
            presses = asyncio.create_task(burst())
            during = []
            while not presses.done() or time.perf_counter() - started < 6:
                during.append(await round_trip(other, slider, 1.2 + 0.1 * (len(during) % 2)))
                await asyncio.sleep(0.3)
            for tab in (other, student):
                await tab.close()
            return quiet, during
        quiet, during = run_async(scenario())
    graded = open_store(None, tmp_path).submissions(code, "s4001")
    span = graded[-1].submitted - graded[0].submitted if graded else 0.0
    print(f"\n100 Submit presses in 2 s: {len(graded)} graded over {span:.1f} s; other tab's slider round "
          f"trip median {statistics.median(during):.0f} ms during (max {max(during):.0f}, n={len(during)}), "
          f"{statistics.median(quiet):.0f} ms quiet")
    assert 1 <= len(graded) <= 100
    assert statistics.median(during) <= max(150, 3 * statistics.median(quiet))
