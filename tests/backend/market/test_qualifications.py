"""Qualification types, grants, requirements on HITs, worker blocks and notifications."""

from __future__ import annotations

import pytest

from tests.backend.market.helpers import (
    OTHER_REQUESTER,
    WORKER,
    WORKER_2,
    WORKER_3,
    MTurk,
    accept,
    create_hit,
    error_of,
    make_client,
    work,
)


def _training_type(client: MTurk, name: str = "Passed hand-tracking training") -> str:
    qtype = client.create_qualification_type(
        Name=name, Description="Finished the tutorial with a passing score",
        Keywords="training, hands", QualificationTypeStatus="Active")["QualificationType"]
    return qtype["QualificationTypeId"]


def _visible_hits(worker_id: str) -> dict[str, tuple[bool, bool]]:
    """HITId -> (can preview, can accept) as the worker's HIT list shows them."""
    from backend.db import session_scope
    from backend.market import clock, workers

    with session_scope() as session:
        return {view.hit.hit_id: (view.can_preview, view.can_accept)
                for view in workers.list_available_hits(session, worker_id, clock.now())}


def test_qualification_types_are_created_and_read_back(mturk: MTurk) -> None:
    type_id = _training_type(mturk)
    qtype = mturk.get_qualification_type(QualificationTypeId=type_id)["QualificationType"]
    assert qtype["Name"] == "Passed hand-tracking training"
    assert qtype["QualificationTypeStatus"] == "Active" and qtype["IsRequestable"] is False
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        _training_type(mturk)
    assert error_of(exc)[1] == "AWS.MechanicalTurk.QualificationTypeAlreadyExists"
    auto = mturk.create_qualification_type(
        Name="Auto", Description="granted on request", QualificationTypeStatus="Inactive",
        AutoGranted=True)["QualificationType"]
    assert (auto["AutoGranted"], auto["AutoGrantedValue"], auto["IsRequestable"]) == (
        True, 1, True)
    with pytest.raises(mturk.exceptions.RequestError, match="Test needs TestDurationInSeconds"):
        mturk.create_qualification_type(Name="Quiz", Description="d", Test="<QuestionForm/>",
                                        QualificationTypeStatus="Active")


def test_granting_and_revoking_shows_in_the_workers_list(mturk: MTurk) -> None:
    type_id = _training_type(mturk)
    for index, worker in enumerate((WORKER, WORKER_2, WORKER_3)):
        mturk.associate_qualification_with_worker(QualificationTypeId=type_id, WorkerId=worker,
                                                  IntegerValue=80 + index, SendNotification=False)
    mturk.disassociate_qualification_from_worker(QualificationTypeId=type_id, WorkerId=WORKER_2,
                                                 Reason="Failed the spot check")
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.disassociate_qualification_from_worker(QualificationTypeId=type_id,
                                                     WorkerId=WORKER_2)
    assert error_of(exc)[1] == "AWS.MechanicalTurk.QualificationDoesNotExist"
    pages = list(mturk.get_paginator("list_workers_with_qualification_type").paginate(
        QualificationTypeId=type_id, PaginationConfig={"PageSize": 2}))
    listed = [(q["WorkerId"], q["Status"], q["IntegerValue"])
              for page in pages for q in page["Qualifications"]]
    assert listed == [(WORKER, "Granted", 80), (WORKER_2, "Revoked", 81),
                      (WORKER_3, "Granted", 82)]
    granted = mturk.list_workers_with_qualification_type(QualificationTypeId=type_id,
                                                         Status="Granted")
    assert [q["WorkerId"] for q in granted["Qualifications"]] == [WORKER, WORKER_3]


def test_only_the_owner_grants_its_qualification_type(market_url: str, mturk: MTurk) -> None:
    type_id = _training_type(mturk)
    other = make_client(market_url, key=OTHER_REQUESTER)
    with pytest.raises(other.exceptions.RequestError) as exc:
        other.associate_qualification_with_worker(QualificationTypeId=type_id, WorkerId=WORKER)
    assert error_of(exc)[1] == "AWS.MechanicalTurk.PermissionDenied"
    assert other.get_qualification_type(QualificationTypeId=type_id)["QualificationType"]


def test_requirements_decide_who_sees_previews_and_accepts(mturk: MTurk) -> None:
    from backend.errors import Forbidden

    type_id = _training_type(mturk)
    mturk.associate_qualification_with_worker(QualificationTypeId=type_id, WorkerId=WORKER,
                                              IntegerValue=90)
    mturk.associate_qualification_with_worker(QualificationTypeId=type_id, WorkerId=WORKER_2,
                                              IntegerValue=50)
    gated = create_hit(mturk, QualificationRequirements=[{
        "QualificationTypeId": type_id, "Comparator": "GreaterThanOrEqualTo",
        "IntegerValues": [70]}])["HITId"]
    hidden = create_hit(mturk, Title="Hidden", QualificationRequirements=[{
        "QualificationTypeId": type_id, "Comparator": "Exists",
        "ActionsGuarded": "DiscoverPreviewAndAccept"}])["HITId"]
    assert _visible_hits(WORKER) == {gated: (True, True), hidden: (True, True)}
    assert _visible_hits(WORKER_2) == {gated: (True, False), hidden: (True, True)}
    assert _visible_hits(WORKER_3) == {gated: (True, False)}
    with pytest.raises(Forbidden, match="qualification requirements"):
        accept(gated, WORKER_2)
    assert accept(gated, WORKER)


def test_locale_and_approval_rate_requirements_use_the_workers_record(
    market_url: str, mturk: MTurk
) -> None:
    from backend.db import session_scope
    from backend.market import clock, workers

    with session_scope() as session:
        workers.get_or_create_worker(session, WORKER, clock.now(), country="US", subdivision="WA")
        workers.get_or_create_worker(session, WORKER_2, clock.now(), country="DE")
    local = create_hit(mturk, QualificationRequirements=[{
        "QualificationTypeId": "00000000000000000071", "Comparator": "In",
        "LocaleValues": [{"Country": "US", "Subdivision": "WA"}, {"Country": "CA"}]}])["HITId"]
    assert _visible_hits(WORKER)[local] == (True, True)
    assert _visible_hits(WORKER_2)[local] == (True, False)
    rejected = work(market_url, create_hit(mturk, Title="Warm-up")["HITId"], WORKER_2)
    mturk.reject_assignment(AssignmentId=rejected, RequesterFeedback="no labels")
    careful = create_hit(mturk, Title="Careful workers", QualificationRequirements=[{
        "QualificationTypeId": "000000000000000000L0", "Comparator": "GreaterThan",
        "IntegerValues": [95]}])["HITId"]
    assert _visible_hits(WORKER)[careful] == (True, True)  # no reviewed work yet: 100%
    assert _visible_hits(WORKER_2)[careful] == (True, False)  # 0 of 1 approved
    with pytest.raises(mturk.exceptions.RequestError, match="takes 1 to 1 values"):
        create_hit(mturk, QualificationRequirements=[{
            "QualificationTypeId": "00000000000000000071", "Comparator": "EqualTo"}])
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        create_hit(mturk, QualificationRequirements=[{
            "QualificationTypeId": "3NOSUCHTYPE", "Comparator": "Exists"}])
    assert error_of(exc)[1] == "AWS.MechanicalTurk.QualificationTypeDoesNotExist"


def test_a_blocked_worker_cannot_find_or_accept_the_requesters_hits(mturk: MTurk) -> None:
    from backend.errors import Forbidden

    hit_id = create_hit(mturk, MaxAssignments=2)["HITId"]
    mturk.create_worker_block(WorkerId=WORKER, Reason="Spam submissions")
    assert hit_id not in _visible_hits(WORKER)
    with pytest.raises(Forbidden):
        accept(hit_id, WORKER)
    mturk.delete_worker_block(WorkerId=WORKER, Reason="Appeal accepted")
    mturk.delete_worker_block(WorkerId=WORKER)  # lifting a missing block succeeds
    assert accept(hit_id, WORKER)


def test_notify_workers_reaches_only_workers_with_reviewed_work(
    market_url: str, mturk: MTurk
) -> None:
    from sqlalchemy import select

    from backend.db import session_scope
    from backend.market.models import Notification

    assignment_id = work(market_url, create_hit(mturk)["HITId"])
    mturk.approve_assignment(AssignmentId=assignment_id)
    result = mturk.notify_workers(Subject="New HITs", MessageText="A new batch is up.",
                                  WorkerIds=[WORKER, WORKER_2])
    failures = result["NotifyWorkersFailureStatuses"]
    assert [(f["WorkerId"], f["NotifyWorkersFailureCode"]) for f in failures] == [
        (WORKER_2, "HardFailure")]
    with session_scope() as session:
        sent = session.scalars(select(Notification.worker_id)).all()
    assert sent == [WORKER]
    with pytest.raises(mturk.exceptions.RequestError, match="Subject must be 1 to 200"):
        mturk.notify_workers(Subject="x" * 201, MessageText="m", WorkerIds=[WORKER])
