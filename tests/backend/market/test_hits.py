"""HIT types and HITs: publish, idempotency, read, list with paginators, extend, expire, delete."""

from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta

import pytest

from tests.backend.market.helpers import (
    MTurk,
    accept,
    create_hit,
    error_of,
    external_question,
    work,
)


def test_create_hit_returns_the_hit_as_published(mturk: MTurk) -> None:
    hit = create_hit(mturk, MaxAssignments=3, RequesterAnnotation="task:17:round:1")
    assert re.fullmatch(r"[A-Z0-9]{30}", hit["HITId"])
    assert hit["HITStatus"] == "Assignable" and hit["Reward"] == "0.50"
    assert hit["NumberOfAssignmentsAvailable"] == 3 and hit["NumberOfAssignmentsPending"] == 0
    assert hit["RequesterAnnotation"] == "task:17:round:1"
    lifetime = hit["Expiration"] - hit["CreationTime"]
    assert lifetime == timedelta(seconds=3600)
    assert mturk.get_hit(HITId=hit["HITId"])["HIT"] == hit


def test_identical_properties_share_one_hit_type(mturk: MTurk) -> None:
    type_id = mturk.create_hit_type(
        Title="Track 21 hand joints", Description="Click each joint through the clip",
        Keywords="hand, keypoints", Reward="0.50", AssignmentDurationInSeconds=600,
        AutoApprovalDelayInSeconds=86400)["HITTypeId"]
    again = mturk.create_hit_type(
        Title="Track 21 hand joints", Description="Click each joint through the clip",
        Keywords="hand, keypoints", Reward="0.50", AssignmentDurationInSeconds=600,
        AutoApprovalDelayInSeconds=86400)["HITTypeId"]
    assert again == type_id
    assert create_hit(mturk)["HITTypeId"] == type_id  # CreateHIT reuses the matching type
    hit = mturk.create_hit_with_hit_type(HITTypeId=type_id, LifetimeInSeconds=600,
                                         MaxAssignments=2, Question=external_question())["HIT"]
    assert hit["HITTypeId"] == type_id and hit["Title"] == "Track 21 hand joints"
    assert hit["MaxAssignments"] == 2
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.create_hit_with_hit_type(HITTypeId="3NOSUCHTYPE", LifetimeInSeconds=600,
                                       Question=external_question())
    assert error_of(exc)[1] == "AWS.MechanicalTurk.HITTypeDoesNotExist"


def test_a_reused_unique_request_token_names_the_existing_hit(mturk: MTurk) -> None:
    first = create_hit(mturk, UniqueRequestToken="task-17-round-1")
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        create_hit(mturk, UniqueRequestToken="task-17-round-1")
    _, turk_code, message = error_of(exc)
    assert turk_code == "AWS.MechanicalTurk.HitAlreadyExists"
    recovered = re.search(r"HITId ([A-Z0-9]+)", message)
    assert recovered is not None and recovered.group(1) == first["HITId"]
    assert mturk.list_hits()["NumResults"] == 1
    balance = mturk.get_account_balance()
    assert balance["OnHoldBalance"] == "0.60"  # held once: reward 0.50 + fee 0.10


def test_a_token_older_than_a_day_creates_a_new_hit(mturk: MTurk) -> None:
    from backend.market import clock

    first = create_hit(mturk, UniqueRequestToken="daily")
    clock.advance(timedelta(hours=25))
    second = create_hit(mturk, UniqueRequestToken="daily")
    assert second["HITId"] != first["HITId"]


@pytest.mark.parametrize(("overrides", "fragment"), [
    ({"Question": "<ExternalQuestion>"}, "not well-formed XML"),
    ({"Question": "<Survey/>"}, "must be an ExternalQuestion, HTMLQuestion or QuestionForm"),
    ({"Question": external_question("ftp://example.org/task")}, "is not an http(s) URL"),
    ({"LifetimeInSeconds": 10}, "LifetimeInSeconds must be between 30"),
    ({"AutoApprovalDelayInSeconds": 40 * 86400}, "AutoApprovalDelayInSeconds must be between"),
    ({"Reward": "1.5.0"}, "Reward"),
    ({"Title": "x" * 200}, "Title may be at most 128"),
])
def test_invalid_hits_are_refused_with_the_member_named(
    mturk: MTurk, overrides: dict, fragment: str
) -> None:
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        create_hit(mturk, **overrides)
    assert fragment in error_of(exc)[2]
    assert mturk.list_hits()["NumResults"] == 0


def test_list_hits_pages_through_every_hit_with_the_paginator(mturk: MTurk) -> None:
    created = [create_hit(mturk, RequesterAnnotation=f"task-{i}")["HITId"] for i in range(7)]
    pages = list(mturk.get_paginator("list_hits").paginate(PaginationConfig={"PageSize": 3}))
    assert [page["NumResults"] for page in pages] == [3, 3, 1]
    assert [hit["HITId"] for page in pages for hit in page["HITs"]] == created
    assert "NextToken" not in pages[-1]
    with pytest.raises(mturk.exceptions.RequestError):
        mturk.list_hits(NextToken="bm90LWEtdG9rZW4=")


def test_hit_moves_from_assignable_to_unassignable_to_reviewable(
    market_url: str, mturk: MTurk
) -> None:
    hit_id = create_hit(mturk, MaxAssignments=2)["HITId"]
    first = accept(hit_id)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Assignable"
    second = accept(hit_id, "A2WORKERTWO")
    hit = mturk.get_hit(HITId=hit_id)["HIT"]
    assert (hit["HITStatus"], hit["NumberOfAssignmentsPending"]) == ("Unassignable", 2)
    from tests.backend.market.helpers import submit

    assert submit(market_url, first, labels="a").status_code == 200
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Unassignable"
    assert submit(market_url, second, labels="b").status_code == 200
    hit = mturk.get_hit(HITId=hit_id)["HIT"]
    assert (hit["HITStatus"], hit["NumberOfAssignmentsPending"]) == ("Reviewable", 0)


def test_expiring_a_hit_makes_it_reviewable_and_extending_reopens_it(mturk: MTurk) -> None:
    hit_id = create_hit(mturk, MaxAssignments=2)["HITId"]
    mturk.update_expiration_for_hit(HITId=hit_id, ExpireAt=datetime(2015, 1, 1, tzinfo=UTC))
    hit = mturk.get_hit(HITId=hit_id)["HIT"]
    assert (hit["HITStatus"], hit["NumberOfAssignmentsAvailable"]) == ("Reviewable", 0)
    assert mturk.get_account_balance()["OnHoldBalance"] == "0.00"  # unfilled slots released
    mturk.update_expiration_for_hit(HITId=hit_id,
                                    ExpireAt=datetime.now(UTC) + timedelta(hours=2))
    hit = mturk.get_hit(HITId=hit_id)["HIT"]
    assert (hit["HITStatus"], hit["NumberOfAssignmentsAvailable"]) == ("Assignable", 2)
    assert mturk.get_account_balance()["OnHoldBalance"] == "1.20"
    with pytest.raises(mturk.exceptions.RequestError, match="at most 365 days"):
        mturk.update_expiration_for_hit(HITId=hit_id,
                                        ExpireAt=datetime.now(UTC) + timedelta(days=400))


def test_a_hit_expires_on_its_own_when_its_lifetime_has_passed(mturk: MTurk) -> None:
    from backend.market import clock

    hit_id = create_hit(mturk, LifetimeInSeconds=60)["HITId"]
    clock.advance(61)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Reviewable"
    balance = mturk.get_account_balance()
    assert (balance["AvailableBalance"], balance["OnHoldBalance"]) == ("10000.00", "0.00")


def test_review_status_moves_between_reviewable_and_reviewing(
    market_url: str, mturk: MTurk
) -> None:
    hit_id = create_hit(mturk)["HITId"]
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.update_hit_review_status(HITId=hit_id)
    assert error_of(exc)[1] == "AWS.MechanicalTurk.InvalidHITState"
    work(market_url, hit_id)
    mturk.update_hit_review_status(HITId=hit_id, Revert=False)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Reviewing"
    listed = mturk.list_reviewable_hits(Status="Reviewing")["HITs"]
    assert [h["HITId"] for h in listed] == [hit_id]
    mturk.update_hit_review_status(HITId=hit_id, Revert=True)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Reviewable"
    with pytest.raises(mturk.exceptions.RequestError):
        mturk.update_hit_review_status(HITId=hit_id, Revert=True)


def test_list_reviewable_hits_pages_with_the_paginator(market_url: str, mturk: MTurk) -> None:
    reviewable = []
    for index in range(5):
        hit_id = create_hit(mturk, RequesterAnnotation=f"r{index}")["HITId"]
        if index % 2 == 0:
            work(market_url, hit_id)
            reviewable.append(hit_id)
    other_type = create_hit(mturk, Title="A different kind of HIT")["HITId"]
    work(market_url, other_type)
    paginator = mturk.get_paginator("list_reviewable_hits")
    pages = list(paginator.paginate(PaginationConfig={"PageSize": 2}))
    assert [h["HITId"] for p in pages for h in p["HITs"]] == reviewable + [other_type]
    assert all(h["HITStatus"] == "Reviewable" for p in pages for h in p["HITs"])
    type_id = mturk.get_hit(HITId=reviewable[0])["HIT"]["HITTypeId"]
    of_type = list(paginator.paginate(HITTypeId=type_id, PaginationConfig={"PageSize": 2}))
    assert [h["HITId"] for p in of_type for h in p["HITs"]] == reviewable


def test_delete_hit_follows_mturks_state_rules(market_url: str, mturk: MTurk) -> None:
    hit_id = create_hit(mturk, MaxAssignments=2)["HITId"]
    accept(hit_id)
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.delete_hit(HITId=hit_id)  # still Assignable
    assert error_of(exc)[1] == "AWS.MechanicalTurk.InvalidHITState"
    mturk.update_expiration_for_hit(HITId=hit_id, ExpireAt=datetime(2015, 1, 1, tzinfo=UTC))
    with pytest.raises(mturk.exceptions.RequestError, match="Unassignable"):
        mturk.delete_hit(HITId=hit_id)  # a worker still holds an assignment
    assert mturk.list_assignments_for_hit(HITId=hit_id)["Assignments"] == []
    from tests.backend.market.helpers import submit

    pending = mturk.get_hit(HITId=hit_id)["HIT"]["NumberOfAssignmentsPending"]
    assert pending == 1
    held = _held_assignment(hit_id)
    assert submit(market_url, held, labels="late but in time").status_code == 200
    with pytest.raises(mturk.exceptions.RequestError, match="not yet approved or rejected"):
        mturk.delete_hit(HITId=hit_id)
    mturk.approve_assignment(AssignmentId=held)
    mturk.delete_hit(HITId=hit_id)
    mturk.delete_hit(HITId=hit_id)  # deleting again is harmless
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Disposed"
    assert mturk.list_hits()["NumResults"] == 0
    assert mturk.get_account_balance()["OnHoldBalance"] == "0.00"


def _held_assignment(hit_id: str) -> str:
    from sqlalchemy import select

    from backend.db import session_scope
    from backend.market.models import Hit, MarketAssignment

    with session_scope() as session:
        stmt = (select(MarketAssignment.assignment_id).join(MarketAssignment.hit)
                .where(Hit.hit_id == hit_id, MarketAssignment.status == "Accepted"))
        return session.scalars(stmt).one()


def test_additional_assignments_are_added_once_per_token(mturk: MTurk) -> None:
    hit_id = create_hit(mturk, MaxAssignments=2)["HITId"]
    mturk.create_additional_assignments_for_hit(
        HITId=hit_id, NumberOfAdditionalAssignments=3, UniqueRequestToken="more-17")
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.create_additional_assignments_for_hit(
            HITId=hit_id, NumberOfAdditionalAssignments=3, UniqueRequestToken="more-17")
    assert "already been processed by request" in error_of(exc)[2]
    hit = mturk.get_hit(HITId=hit_id)["HIT"]
    assert (hit["MaxAssignments"], hit["NumberOfAssignmentsAvailable"]) == (5, 5)
    assert mturk.get_account_balance()["OnHoldBalance"] == "3.00"


def test_a_hit_under_ten_assignments_cannot_grow_to_ten(mturk: MTurk) -> None:
    hit_id = create_hit(mturk, MaxAssignments=9)["HITId"]
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.create_additional_assignments_for_hit(HITId=hit_id, NumberOfAdditionalAssignments=1)
    assert error_of(exc)[1] == "AWS.MechanicalTurk.InvalidMaximumAssignmentsIncrease"
    large = create_hit(mturk, MaxAssignments=10)["HITId"]
    mturk.create_additional_assignments_for_hit(HITId=large, NumberOfAdditionalAssignments=5)
    assert mturk.get_hit(HITId=large)["HIT"]["MaxAssignments"] == 15
