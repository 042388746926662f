"""Assignments: the worker's accept/submit/return, the requester's review, and the clock."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from datetime import timedelta

import pytest

from tests.backend.market.helpers import (
    ANSWERS_NS,
    WORKER,
    WORKER_2,
    WORKER_3,
    MTurk,
    accept,
    create_hit,
    error_of,
    submit,
    work,
)


def _answers(answer_xml: str) -> dict[str, str]:
    root = ET.fromstring(answer_xml)
    assert root.tag == f"{{{ANSWERS_NS}}}QuestionFormAnswers"
    ns = {"a": ANSWERS_NS}
    return {a.findtext("a:QuestionIdentifier", namespaces=ns): a.findtext("a:FreeText",
                                                                         namespaces=ns)
            for a in root.findall("a:Answer", ns)}


def test_external_submit_stores_one_answer_per_form_field(market_url: str, mturk: MTurk) -> None:
    hit_id = create_hit(mturk)["HITId"]
    assignment_id = accept(hit_id)
    resp = submit(market_url, assignment_id, tracks='{"points": [[0, 12.5, 40, 1]]}',
                  comment="wrist hidden <frames 3-5> & more", workerId=WORKER)
    assert resp.status_code == 200 and "Submitted, thank you" in resp.text
    got = mturk.get_assignment(AssignmentId=assignment_id)
    assignment = got["Assignment"]
    assert assignment["AssignmentStatus"] == "Submitted" and assignment["WorkerId"] == WORKER
    assert _answers(assignment["Answer"]) == {
        "tracks": '{"points": [[0, 12.5, 40, 1]]}',
        "comment": "wrist hidden <frames 3-5> & more", "workerId": WORKER}
    assert got["HIT"]["HITId"] == hit_id
    assert assignment["AutoApprovalTime"] - assignment["SubmitTime"] == timedelta(days=1)
    listed = mturk.list_assignments_for_hit(HITId=hit_id)["Assignments"]
    assert [a["Answer"] for a in listed] == [assignment["Answer"]]


def test_external_submit_refuses_unknown_and_closed_assignments(
    market_url: str, mturk: MTurk
) -> None:
    resp = submit(market_url, "3NOSUCHASSIGNMENT", labels="x")
    assert resp.status_code == 400 and "does not exist" in resp.text
    assignment_id = work(market_url, create_hit(mturk)["HITId"])
    resp = submit(market_url, assignment_id, labels="again")
    assert resp.status_code == 400 and "already submitted" in resp.text
    import httpx

    resp = httpx.post(f"{market_url}/mturk/externalSubmit", data={"labels": "x"})
    assert resp.status_code == 400 and "no assignmentId" in resp.text


def test_work_in_progress_is_invisible_to_the_requester(mturk: MTurk) -> None:
    hit_id = create_hit(mturk)["HITId"]
    assignment_id = accept(hit_id)
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.get_assignment(AssignmentId=assignment_id)
    assert error_of(exc)[1] == "AWS.MechanicalTurk.AssignmentDoesNotExist"
    assert mturk.list_assignments_for_hit(HITId=hit_id)["NumResults"] == 0


def test_list_assignments_pages_and_filters_by_status(market_url: str, mturk: MTurk) -> None:
    hit_id = create_hit(mturk, MaxAssignments=5)["HITId"]
    done = [work(market_url, hit_id, f"A{i}WORKER") for i in range(5)]
    mturk.approve_assignment(AssignmentId=done[0])
    mturk.reject_assignment(AssignmentId=done[1], RequesterFeedback="joints swapped")
    pages = list(mturk.get_paginator("list_assignments_for_hit").paginate(
        HITId=hit_id, PaginationConfig={"PageSize": 2}))
    assert [p["NumResults"] for p in pages] == [2, 2, 1]
    assert [a["AssignmentId"] for p in pages for a in p["Assignments"]] == done
    reviewed = mturk.list_assignments_for_hit(HITId=hit_id,
                                              AssignmentStatuses=["Approved", "Rejected"])
    assert {a["AssignmentStatus"] for a in reviewed["Assignments"]} == {"Approved", "Rejected"}
    assert mturk.get_hit(HITId=hit_id)["HIT"]["NumberOfAssignmentsCompleted"] == 2


def test_approving_twice_is_an_invalid_assignment_state(market_url: str, mturk: MTurk) -> None:
    assignment_id = work(market_url, create_hit(mturk)["HITId"])
    mturk.approve_assignment(AssignmentId=assignment_id, RequesterFeedback="Thanks!")
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.approve_assignment(AssignmentId=assignment_id)
    _, turk_code, message = error_of(exc)
    assert turk_code == "AWS.MechanicalTurk.InvalidAssignmentState"
    assert "is Approved" in message
    assignment = mturk.get_assignment(AssignmentId=assignment_id)["Assignment"]
    assert assignment["RequesterFeedback"] == "Thanks!" and "ApprovalTime" in assignment


def test_an_approved_assignment_cannot_be_rejected(market_url: str, mturk: MTurk) -> None:
    assignment_id = work(market_url, create_hit(mturk)["HITId"])
    mturk.approve_assignment(AssignmentId=assignment_id)
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.reject_assignment(AssignmentId=assignment_id, RequesterFeedback="too late")
    assert error_of(exc)[1] == "AWS.MechanicalTurk.InvalidAssignmentState"


def test_rejection_needs_feedback_the_worker_can_read(market_url: str, mturk: MTurk) -> None:
    assignment_id = work(market_url, create_hit(mturk)["HITId"])
    with pytest.raises(mturk.exceptions.RequestError, match="RequesterFeedback is required"):
        mturk.reject_assignment(AssignmentId=assignment_id, RequesterFeedback="   ")
    with pytest.raises(mturk.exceptions.RequestError, match="at most 1024"):
        mturk.reject_assignment(AssignmentId=assignment_id, RequesterFeedback="x" * 1025)
    mturk.reject_assignment(AssignmentId=assignment_id, RequesterFeedback="Index and ring swapped")
    assignment = mturk.get_assignment(AssignmentId=assignment_id)["Assignment"]
    assert assignment["AssignmentStatus"] == "Rejected" and "RejectionTime" in assignment


def test_a_rejection_can_be_overridden_and_is_then_paid(market_url: str, mturk: MTurk) -> None:
    hit_id = create_hit(mturk)["HITId"]
    assignment_id = work(market_url, hit_id)
    mturk.reject_assignment(AssignmentId=assignment_id, RequesterFeedback="looked wrong")
    assert mturk.get_account_balance()["AvailableBalance"] == "10000.00"
    with pytest.raises(mturk.exceptions.RequestError, match="OverrideRejection"):
        mturk.approve_assignment(AssignmentId=assignment_id)
    mturk.approve_assignment(AssignmentId=assignment_id, OverrideRejection=True,
                             RequesterFeedback="my mistake")
    assignment = mturk.get_assignment(AssignmentId=assignment_id)["Assignment"]
    assert assignment["AssignmentStatus"] == "Approved" and "RejectionTime" not in assignment
    assert mturk.get_account_balance()["AvailableBalance"] == "9999.40"


def test_an_abandoned_assignment_frees_its_slot_after_the_duration(mturk: MTurk) -> None:
    from backend.market import clock

    hit_id = create_hit(mturk, AssignmentDurationInSeconds=300)["HITId"]
    assignment_id = accept(hit_id)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Unassignable"
    clock.advance(299)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Unassignable"
    clock.advance(2)
    hit = mturk.get_hit(HITId=hit_id)["HIT"]
    assert (hit["HITStatus"], hit["NumberOfAssignmentsAvailable"]) == ("Assignable", 1)
    assert accept(hit_id, WORKER_2) != assignment_id


def test_submitted_work_is_approved_and_paid_at_auto_approval_time(
    market_url: str, mturk: MTurk
) -> None:
    from backend.market import clock

    hit_id = create_hit(mturk, AutoApprovalDelayInSeconds=3600)["HITId"]
    assignment_id = work(market_url, hit_id)
    assert mturk.get_account_balance()["OnHoldBalance"] == "0.60"
    clock.advance(timedelta(minutes=59))
    assert mturk.get_assignment(AssignmentId=assignment_id)["Assignment"][
        "AssignmentStatus"] == "Submitted"
    clock.advance(timedelta(minutes=2))
    balance = mturk.get_account_balance()  # settles what fell due before answering
    assert (balance["AvailableBalance"], balance["OnHoldBalance"]) == ("9999.40", "0.00")
    assignment = mturk.get_assignment(AssignmentId=assignment_id)["Assignment"]
    assert assignment["AssignmentStatus"] == "Approved"
    assert assignment["ApprovalTime"] == assignment["AutoApprovalTime"]
    with pytest.raises(mturk.exceptions.RequestError):
        mturk.reject_assignment(AssignmentId=assignment_id, RequesterFeedback="too late")


def test_a_returned_assignment_frees_its_slot_and_cannot_be_submitted(
    market_url: str, mturk: MTurk
) -> None:
    from backend.db import session_scope
    from backend.market import clock, workers

    hit_id = create_hit(mturk)["HITId"]
    assignment_id = accept(hit_id)
    with session_scope() as session:
        workers.return_assignment(session, WORKER, assignment_id, clock.now())
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Assignable"
    resp = submit(market_url, assignment_id, labels="x")
    assert resp.status_code == 400 and "was returned" in resp.text


def test_a_worker_takes_one_assignment_per_hit_and_none_of_a_full_hit(mturk: MTurk) -> None:
    from backend.errors import Conflict

    hit_id = create_hit(mturk)["HITId"]
    accept(hit_id)
    with pytest.raises(Conflict, match="already work on"):
        accept(hit_id)
    with pytest.raises(Conflict, match="no assignment left"):
        accept(hit_id, WORKER_3)
