"""A worker's HITs through the portal: list, preview, accept, return, submit, and the money."""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

from backend.config import get_settings
from tests.market.helpers import MTurk, create_hit, external_question, submit
from tests.portal.conftest import Portal

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


def test_earnings_count_approved_rewards_and_bonuses_and_show_feedback(
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
