"""The provider registry and the mturk provider at the edge: the CreateHIT it sends, and
MTurk's answers as provider-neutral reasons (botocore's Stubber stands in for AWS, which
cannot be reached here)."""

from __future__ import annotations

from typing import Any

import pytest
from botocore.stub import ANY, Stubber

from backend.config import Settings
from backend.crowd.provider import (
    BonusOrder,
    CrowdProvider,
    ProviderError,
    ProviderRefused,
    Requirements,
    UnitSpec,
)
from backend.crowd.providers import UnknownProvider, get_provider
from backend.crowd.providers.mturk import EXTERNAL_QUESTION_NS, FEES, MTurkProvider
from backend.crowd.providers.mturk_client import make_client

AWS = {"mturk_use_aws": True, "mturk_access_key_id": "AKIAEXAMPLEEXAMPLE00",
       "mturk_secret_access_key": "example-secret-example-secret"}
UNIT = UnitSpec(key="dxhit-1-1-abc", task_id=1, title="Hand joints", description="Click",
                keywords="hand", page_url="https://labels.example.org/annotate/?task=t&x=1",
                reward_cents=50, places=2, lifetime_s=3600, allotted_s=600, auto_approve_s=60,
                expected_s=300, frame_height=900, note="dexlabel task 1 round 1",
                requirements=Requirements(min_approval_rate=95, locales=("US",), group="Q1"))


def _provider() -> tuple[MTurkProvider, Stubber]:
    settings = Settings(public_url="http://127.0.0.1:8000", **AWS)  # type: ignore[arg-type]
    client = make_client(settings, attempts=1)
    return MTurkProvider(settings, client=client), Stubber(client)


def _error(stub: Stubber, operation: str, code: str, message: str, status: int = 400) -> None:
    stub.add_client_error(operation, service_error_code=code, service_message=message,
                          http_status_code=status, response_meta={}, modeled_fields={})


def test_the_setting_names_the_default_provider_and_an_unknown_one_is_refused() -> None:
    provider = get_provider(settings=Settings())
    assert isinstance(provider, CrowdProvider) and provider.name == "mturk"
    with pytest.raises(UnknownProvider, match="choose one of mturk, prolific, team") as exc:
        get_provider("mechanical")
    assert exc.value.status_code == 422 and exc.value.extra["field"] == "provider"


def test_publish_sends_todays_create_hit_and_recovers_a_hit_published_before() -> None:
    provider, stub = _provider()
    expected: dict[str, Any] = {
        "Title": "Hand joints", "Description": "Click", "Keywords": "hand", "Reward": "0.50",
        "MaxAssignments": 2, "LifetimeInSeconds": 3600, "AssignmentDurationInSeconds": 600,
        "AutoApprovalDelayInSeconds": 60, "RequesterAnnotation": "dexlabel task 1 round 1",
        "UniqueRequestToken": "dxhit-1-1-abc", "Question": ANY,
        "QualificationRequirements": [
            {"QualificationTypeId": "000000000000000000L0", "Comparator": "GreaterThanOrEqualTo",
             "IntegerValues": [95], "ActionsGuarded": "Accept"},
            {"QualificationTypeId": "00000000000000000071", "Comparator": "In",
             "LocaleValues": [{"Country": "US"}], "ActionsGuarded": "Accept"},
            {"QualificationTypeId": "Q1", "Comparator": "Exists",
             "ActionsGuarded": "DiscoverPreviewAndAccept"}]}
    with stub:
        stub.add_response("create_hit", {"HIT": {"HITId": "3HITONE"}}, expected)
        _error(stub, "create_hit", "RequestError",
               "There is already a HIT which exists with the same token: HITId 3HITTWO.")
        provider.client.meta.events.register("after-call.mturk.CreateHIT",
                                             _turk_code("HitAlreadyExists"))
        first = provider.publish([UNIT])
        again = provider.publish([UNIT])
    assert [(u.unit_id, u.outcome) for u in first + again] == [("3HITONE", "created"),
                                                                ("3HITTWO", "recovered")]


def test_the_external_question_frames_the_page_with_its_address_escaped() -> None:
    from backend.crowd.providers.mturk import hit_params

    question = hit_params(UNIT)["Question"]
    assert EXTERNAL_QUESTION_NS in question and "task=t&amp;x=1" in question
    assert "<FrameHeight>900</FrameHeight>" in question


@pytest.mark.parametrize(("code", "message", "status", "reason"), [
    ("RequestError", "This operation can be called with a status of: Submitted", 400, "other"),
    ("ServiceUnavailable", "try again", 503, "throttled"),
    ("RequestError", "Assignment 3X does not exist. (1700000000000)", 400, "not_found"),
])
def test_mturk_answers_become_reasons(code: str, message: str, status: int,
                                      reason: str) -> None:
    provider, stub = _provider()
    _error(stub, "create_worker_block", code, message, status)
    with stub, pytest.raises(ProviderError) as exc:
        provider.block("A1WORKER", "spam")
    assert exc.value.reason == reason and exc.value.operation == "create_worker_block"
    assert exc.value.retryable == (reason == "throttled")


def test_a_refused_value_is_422_naming_our_field() -> None:
    provider, stub = _provider()
    _error(stub, "notify_workers", "ValidationException",
           "1 validation error: MessageText must be 1 to 4096 characters")
    with stub, pytest.raises(ProviderRefused) as exc:
        provider.notify(["A1WORKER"], "hello", "x")
    assert exc.value.status_code == 422 and exc.value.code == "marketplace_refused"
    assert [f["field"] for f in exc.value.extra["fields"]] == ["message"]


def test_a_decision_made_before_and_a_replayed_bonus_are_not_errors() -> None:
    provider, stub = _provider()
    order = BonusOrder(key="dxbonus-1-abc", assignment_id="3ASSIGN", unit_id="3HIT",
                       worker_id="A1WORKER", amount_cents=100, reason="thanks")
    with stub:
        stub.add_client_error("approve_assignment", service_error_code="RequestError",
                              service_message="already approved", http_status_code=400,
                              response_meta={}, modeled_fields={})
        stub.add_response("get_assignment", {"Assignment": {
            "AssignmentId": "3ASSIGN", "HITId": "3HIT", "WorkerId": "A1WORKER",
            "AssignmentStatus": "Approved"}}, {"AssignmentId": "3ASSIGN"})
        _error(stub, "send_bonus", "RequestError",
               "The request with this token has already been processed.")
        provider.client.meta.events.register(  # the TurkErrorCode MTurk sends
            "after-call.mturk.ApproveAssignment", _turk_code("InvalidAssignmentState"))
        provider.approve("3ASSIGN", None)
        provider.pay_bonus(order)


def _turk_code(code: str) -> Any:
    """An after-call hook adding MTurk's TurkErrorCode to a stubbed error (the Stubber cannot
    set it)."""
    def add(parsed: dict[str, Any], **_: Any) -> None:
        if "Error" in parsed:
            parsed["TurkErrorCode"] = f"AWS.MechanicalTurk.{code}"
    return add


def test_mturk_fees_are_its_published_pricing() -> None:
    assert (FEES.reward_fee_cents(50), FEES.reward_fee_cents(50, 10)) == (10, 20)
    assert (FEES.reward_fee_cents(2), FEES.bonus_fee_cents(125)) == (1, 25)
    assert (FEES.provider, FEES.currency) == ("mturk", "USD")
