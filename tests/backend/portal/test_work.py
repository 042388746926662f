"""A worker's HITs through the portal: list, preview, accept, return, submit, and the money."""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

import pytest
from sqlalchemy import select

from backend.config import get_settings
from tests.backend.market.helpers import MTurk, create_hit, external_question, submit
from tests.backend.portal.conftest import Portal

PAGE = "https://label.example.org/annotate/?task=T0K3N"


def _hit(mturk: MTurk, **overrides) -> dict:
    return create_hit(mturk, Question=external_question(PAGE, 700), **overrides)


def test_accept_gives_the_page_url_as_mturk_frames_it(portal: Portal, mturk: MTurk) -> None:
    hit = _hit(mturk, Reward="0.75", MaxAssignments=2)
    worker = portal.new_worker("amy@example.org")
    token = worker["access_token"]
    listed = portal.ok("GET", "/hits", token)
    assert [(h["hit_id"], h["reward"], h["available"]) for h in listed] == [
        (hit["HITId"], "0.75", 2)]
    preview = portal.ok("GET", f"/hits/{hit['HITId']}", token)
    query = parse_qs(urlsplit(preview["preview_url"]).query)
    assert query["assignmentId"] == ["ASSIGNMENT_ID_NOT_AVAILABLE"] and query["task"] == ["T0K3N"]
    assert preview["frame_height"] == 700

    accepted = portal.ok("POST", f"/hits/{hit['HITId']}/accept", token)
    url = urlsplit(accepted["work_url"])
    assert f"{url.scheme}://{url.netloc}{url.path}" == PAGE.split("?")[0]
    assert parse_qs(url.query) == {
        "task": ["T0K3N"], "assignmentId": [accepted["assignment_id"]], "hitId": [hit["HITId"]],
        "workerId": [worker["worker_id"]], "turkSubmitTo": [get_settings().public_url.rstrip("/")]}
    assert accepted["status"] == "Accepted"
    assert portal.ok("GET", "/hits", token) == []  # one assignment per worker and HIT
    again = portal.call("POST", f"/hits/{hit['HITId']}/accept", token)
    assert again.status_code == 409
    seen = mturk.list_assignments_for_hit(HITId=hit["HITId"], AssignmentStatuses=["Submitted"])
    assert seen["NumResults"] == 0


def test_returned_assignment_frees_the_slot_and_stays_in_the_history(
    portal: Portal, mturk: MTurk
) -> None:
    hit = _hit(mturk)
    ben, cat = portal.new_worker("ben@example.org"), portal.new_worker("cat@example.org")
    accepted = portal.ok("POST", f"/hits/{hit['HITId']}/accept", ben["access_token"])
    assert portal.ok("GET", "/hits", cat["access_token"]) == []  # all taken
    path = f"/assignments/{accepted['assignment_id']}/return"
    assert portal.call("POST", path, cat["access_token"]).status_code == 404
    returned = portal.ok("POST", path, ben["access_token"])
    assert returned["status"] == "Returned" and returned["work_url"] is None
    assert [h["hit_id"] for h in portal.ok("GET", "/hits", cat["access_token"])] == [hit["HITId"]]
    assert portal.call("POST", path, ben["access_token"]).status_code == 409
    history = portal.ok("GET", "/assignments", ben["access_token"])["assignments"]
    assert [(a["assignment_id"], a["status"]) for a in history] == [
        (accepted["assignment_id"], "Returned")]


def test_hits_the_worker_does_not_qualify_for_are_not_listed(portal: Portal, mturk: MTurk) -> None:
    qtype = mturk.create_qualification_type(
        Name="passed training", Description="hand joints training",
        QualificationTypeStatus="Active")["QualificationType"]
    _hit(mturk, QualificationRequirements=[{
        "QualificationTypeId": qtype["QualificationTypeId"], "Comparator": "Exists",
        "ActionsGuarded": "DiscoverPreviewAndAccept"}])
    dan = portal.new_worker("dan@example.org")
    assert portal.ok("GET", "/hits", dan["access_token"]) == []
    mturk.associate_qualification_with_worker(
        QualificationTypeId=qtype["QualificationTypeId"], WorkerId=dan["worker_id"],
        IntegerValue=1, SendNotification=False)
    assert len(portal.ok("GET", "/hits", dan["access_token"])) == 1


def test_earnings_count_accepted_rewards_and_bonuses_and_show_feedback(
    portal: Portal, mturk: MTurk
) -> None:
    paid_hit, waiting_hit = _hit(mturk, Reward="0.50"), _hit(mturk, Reward="0.30")
    eve = portal.new_worker("eve@example.org")
    token = eve["access_token"]
    done = [portal.ok("POST", f"/hits/{h['HITId']}/accept", token)["assignment_id"]
            for h in (paid_hit, waiting_hit)]
    for assignment_id in done:
        assert submit(portal.base, assignment_id, result="submitted:3").status_code == 200
    mturk.approve_assignment(AssignmentId=done[0], RequesterFeedback="Clean tracks, thanks")
    mturk.send_bonus(WorkerId=eve["worker_id"], BonusAmount="0.25", AssignmentId=done[0],
                     Reason="careful occlusion flags", UniqueRequestToken="portal-bonus-1")

    mine = portal.ok("GET", "/assignments", token)
    assert mine["earnings"] == {"paid": "0.75", "pending": "0.30", "bonuses": "0.25"}
    rows = {a["assignment_id"]: a for a in mine["assignments"]}
    assert rows[done[0]]["status"] == "Approved" and rows[done[0]]["bonus"] == "0.25"
    assert rows[done[0]]["feedback"] == "Clean tracks, thanks"
    assert rows[done[1]]["status"] == "Submitted" and rows[done[1]]["work_url"] is None
    one = portal.ok("GET", f"/assignments/{done[1]}", token)
    assert one["reward"] == "0.30" and one["submit_time"] is not None
    other = portal.new_worker("fin@example.org")
    assert portal.call("GET", f"/assignments/{done[1]}", other["access_token"]).status_code == 404


def test_a_crowd_listing_and_accepting_at_once_never_gets_a_server_error(
    portal: Portal, mturk: MTurk
) -> None:
    """Listing HITs settles what the clock made due on each HIT it shows, a write that can
    race with another worker's accept of the same HIT; the loser lists again, it never
    answers 500."""
    from concurrent.futures import ThreadPoolExecutor

    hits = [_hit(mturk, MaxAssignments=4)["HITId"] for _ in range(3)]
    workers = [portal.new_worker(f"crowd{i}@example.org")["access_token"] for i in range(12)]

    def work(token: str) -> list[int]:
        codes = []
        for _ in range(4):
            listed = portal.call("GET", "/hits", token)
            codes.append(listed.status_code)
            if listed.status_code == 200 and listed.json():
                accept = portal.call("POST", f"/hits/{listed.json()[0]['hit_id']}/accept", token)
                codes.append(accept.status_code)
        return codes

    with ThreadPoolExecutor(len(workers)) as pool:
        codes = [c for done in pool.map(work, workers) for c in done]
    assert 500 not in codes, codes
    assert set(codes) <= {200, 409, 503}, codes
    # Every worker holds one of the 12 slots (one assignment per worker and HIT; a worker
    # whose listing came back empty had seen the other HITs taken).
    held = [[a["hit_id"] for a in portal.ok("GET", "/assignments", token)["assignments"]
             if a["status"] == "Accepted"] for token in workers]
    assert sum(map(len, held)) == 12 and {h for one in held for h in one} == set(hits)


def test_a_listing_that_loses_a_race_on_a_hit_lists_again_instead_of_failing(
    portal: Portal, mturk: MTurk, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Listing settles what the clock made due on each HIT it shows (here: approving a
    submission whose auto-approval time passed, paying it from the HIT's hold). Another
    request settles the same HIT first and commits; the listing's write then matches no row
    (the HIT's version moved on), so it lists again from the winner's state: no error, the
    HIT shown, the work paid once."""
    from datetime import timedelta

    from backend.db import session_scope
    from backend.market import clock, lifecycle, workers
    from backend.market.models import Hit

    hit = _hit(mturk, Reward="0.40", MaxAssignments=2, AutoApprovalDelayInSeconds=60)["HITId"]
    ben, cat = portal.new_worker("ben@example.org"), portal.new_worker("cat@example.org")
    done = portal.ok("POST", f"/hits/{hit}/accept", ben["access_token"])["assignment_id"]
    assert submit(portal.base, done, result="submitted:3").status_code == 200
    clock.advance(timedelta(minutes=5))  # ben's submission is due for auto-approval
    real, raced = lifecycle.refresh_hit, []

    def refresh_after_a_rival(session, listed: Hit, now, payer=None):  # type: ignore[no-untyped-def]
        if not raced:  # another request settles the same HIT first, and commits
            raced.append(listed.hit_id)
            with session_scope() as rival:
                real(rival, rival.scalars(select(Hit).where(Hit.hit_id == listed.hit_id)).one(),
                     now)
        return real(session, listed, now, payer)

    monkeypatch.setattr(workers.lifecycle, "refresh_hit", refresh_after_a_rival)
    try:
        listed = portal.call("GET", "/hits", cat["access_token"])
    finally:
        clock.reset()
    assert raced == [hit]
    assert listed.status_code == 200, listed.text
    assert [(h["hit_id"], h["available"]) for h in listed.json()] == [(hit, 1)]
    assert portal.ok("GET", "/assignments", ben["access_token"])["earnings"]["paid"] == "0.40"
