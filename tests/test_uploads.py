"""The upload policy of app/infra/uploads.py: one unfinished upload per tab, a budget per process,
stale uploads dropped."""

from app.infra.uploads import UPLOAD_STALE_S, Uploads


def test_a_new_upload_replaces_the_tabs_unfinished_one():
    uploads = Uploads(budget=100)
    assert uploads.start(1, "a", 40, now=0.0) == (True, [])
    assert uploads.part(1, "a", 10, now=1.0) == "more"
    accepted, dropped = uploads.start(1, "b", 40, now=2.0)
    assert accepted and dropped == [(1, "a")]
    assert uploads.part(1, "a", 10, now=2.5) is None          # the dropped upload's parts are not passed on
    assert uploads.reserved() == 40


def test_the_process_budget_refuses_uploads_beyond_it():
    uploads = Uploads(budget=100)
    assert uploads.start(1, "a", 60, now=0.0)[0]
    assert not uploads.start(2, "a", 60, now=0.0)[0]          # the same transfer name from another tab
    assert uploads.start(2, "b", 40, now=0.0)[0]
    assert uploads.part(1, "a", 60, now=1.0) == "done"
    assert uploads.start(3, "c", 60, now=1.0)[0] and uploads.reserved() == 100


def test_stale_uploads_are_dropped_and_overflow_ends_an_upload():
    uploads = Uploads(budget=100)
    uploads.start(1, "a", 50, now=0.0)
    uploads.start(2, "b", 30, now=0.0)
    uploads.part(2, "b", 10, now=UPLOAD_STALE_S - 1)
    accepted, dropped = uploads.start(3, "c", 60, now=UPLOAD_STALE_S + 0.5)
    assert accepted and dropped == [(1, "a")]                 # silent since it began; b sent a part lately
    assert uploads.part(2, "b", 25, now=UPLOAD_STALE_S) == "overflow"
    assert uploads.of_client(2) == [] and uploads.of_client(3) == [(3, "c")]

