"""The wire protocol: SigV4, X-Amz-Target dispatch, validation against botocore's model, errors."""

from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta

import botocore.auth
import httpx
import pytest
from botocore.exceptions import ClientError, ParamValidationError

from tests.backend.market.helpers import (
    OTHER_REQUESTER,
    REQUESTER,
    MTurk,
    create_hit,
    error_of,
    hit_params,
    make_client,
    signed_post,
)

LISTED_OPERATIONS = {
    "CreateHIT", "CreateHITType", "CreateHITWithHITType", "GetHIT", "ListHITs",
    "ListReviewableHITs", "UpdateExpirationForHIT", "UpdateHITReviewStatus", "DeleteHIT",
    "CreateAdditionalAssignmentsForHIT", "ListAssignmentsForHIT", "GetAssignment",
    "ApproveAssignment", "RejectAssignment", "SendBonus", "ListBonusPayments",
    "GetAccountBalance", "CreateQualificationType", "GetQualificationType",
    "AssociateQualificationWithWorker", "DisassociateQualificationFromWorker",
    "ListWorkersWithQualificationType", "CreateWorkerBlock", "DeleteWorkerBlock", "NotifyWorkers",
}


def test_every_listed_operation_has_a_handler_in_the_service_model() -> None:
    from backend.market.operations import HANDLERS
    from backend.market.validation import service_model

    assert set(HANDLERS) == LISTED_OPERATIONS
    assert set(service_model().operation_names) >= LISTED_OPERATIONS


def test_unknown_access_key_is_an_unrecognized_client(market_url: str) -> None:
    client = make_client(market_url, key=("AKIANOTAREQUESTER000", "whatever-secret"))
    with pytest.raises(ClientError) as exc:
        client.get_account_balance()
    assert exc.value.response["Error"]["Code"] == "UnrecognizedClientException"
    assert exc.value.response["ResponseMetadata"]["HTTPStatusCode"] == 400


def test_wrong_secret_fails_the_signature_check(market_url: str) -> None:
    client = make_client(market_url, key=(REQUESTER[0], "not-the-secret"))
    with pytest.raises(ClientError) as exc:
        client.get_account_balance()
    code, _, message = error_of(exc)
    assert code == "InvalidSignatureException" and REQUESTER[0] in message


def test_request_without_authorization_is_refused(market_url: str) -> None:
    resp = httpx.post(f"{market_url}/mturk", content=b"{}", headers={
        "X-Amz-Target": "MTurkRequesterServiceV20170117.GetAccountBalance",
        "Content-Type": "application/x-amz-json-1.1"})
    assert resp.status_code == 400
    assert resp.json()["__type"] == "MissingAuthenticationTokenException"


def test_tampered_body_fails_the_signature_check(market_url: str) -> None:
    from botocore.auth import SigV4Auth
    from botocore.awsrequest import AWSRequest
    from botocore.credentials import Credentials

    request = AWSRequest(method="POST", url=f"{market_url}/mturk", data=b'{"HITId": "3AAA"}',
                         headers={"X-Amz-Target": "MTurkRequesterServiceV20170117.GetHIT",
                                  "Content-Type": "application/x-amz-json-1.1"})
    SigV4Auth(Credentials(*REQUESTER), "mturk-requester", "us-east-1").add_auth(request)
    resp = httpx.post(request.url, content=b'{"HITId": "3BBB"}',
                      headers=dict(request.headers.items()))
    assert resp.status_code == 400 and resp.json()["__type"] == "InvalidSignatureException"


def test_signature_older_than_fifteen_minutes_has_expired(
    market_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    stale = datetime.now(UTC).replace(tzinfo=None) - timedelta(minutes=20)
    monkeypatch.setattr(botocore.auth, "get_current_datetime", lambda: stale)
    resp = signed_post(market_url, "GetAccountBalance", {})
    assert resp.status_code == 400
    assert resp.json()["__type"] == "InvalidSignatureException"
    assert "expired" in resp.json()["message"]


def test_a_pattern_botocore_does_not_check_is_refused_by_the_service(mturk: MTurk) -> None:
    # botocore checks only minimum lengths: a lower-case HITId reaches the service.
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.get_hit(HITId="3abc-not-an-id")
    code, turk_code, message = error_of(exc)
    assert (code, turk_code) == ("RequestError", "ParameterValidationError")
    assert "HITId" in message and "^[A-Z0-9]+$" in message


def test_max_results_above_one_hundred_is_refused(mturk: MTurk) -> None:
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.list_hits(MaxResults=500)
    assert "MaxResults must be between 1 and 100" in error_of(exc)[2]


def test_an_enum_violation_is_refused_with_the_member_named(mturk: MTurk) -> None:
    requirement = {"QualificationTypeId": "00000000000000000071", "Comparator": "Roughly",
                   "LocaleValues": [{"Country": "US"}]}
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        create_hit(mturk, QualificationRequirements=[requirement])
    assert "QualificationRequirements[0].Comparator 'Roughly' is not one of" in error_of(exc)[2]


def test_wrong_types_and_unknown_members_sent_raw_are_refused(
    market_url: str, mturk: MTurk
) -> None:
    with pytest.raises(ParamValidationError):
        create_hit(mturk, MaxAssignments="three")  # boto3 refuses before sending
    body = {**hit_params(MaxAssignments="three"), "Colour": "blue"}
    resp = signed_post(market_url, "CreateHIT", body)
    assert resp.status_code == 400
    error = resp.json()
    assert error["__type"] == "RequestError"
    assert error["TurkErrorCode"] == "ParameterValidationError"
    assert "MaxAssignments must be an integer" in error["Message"]
    assert "Colour is not a member of CreateHITRequest" in error["Message"]


def test_reject_without_feedback_is_refused_on_both_sides(market_url: str, mturk: MTurk) -> None:
    with pytest.raises(ParamValidationError, match="RequesterFeedback"):
        mturk.reject_assignment(AssignmentId="3ABC")
    resp = signed_post(market_url, "RejectAssignment", {"AssignmentId": "3ABC"})
    assert resp.status_code == 400
    assert resp.json()["TurkErrorCode"] == "ParameterValidationError"
    assert "RequesterFeedback is required" in resp.json()["Message"]


def test_unknown_target_and_bad_json_are_framing_errors(market_url: str) -> None:
    resp = signed_post(market_url, "DoSomethingElse", {})
    assert resp.json()["__type"] == "UnknownOperationException"
    resp = signed_post(market_url, "GetAccountBalance", None, raw=b"{not json")
    assert resp.status_code == 400 and resp.json()["__type"] == "SerializationException"


def test_an_operation_this_marketplace_does_not_offer_says_so(mturk: MTurk) -> None:
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.list_qualification_types(MustBeRequestable=False)
    assert error_of(exc)[1] == "AWS.MechanicalTurk.UnsupportedOperation"


def test_errors_carry_turk_code_and_a_timestamped_message(mturk: MTurk) -> None:
    with pytest.raises(ClientError) as exc:
        mturk.get_hit(HITId="3NOSUCHHIT")
    code, turk_code, message = error_of(exc)
    assert code == "RequestError" and turk_code == "AWS.MechanicalTurk.HITDoesNotExist"
    assert re.fullmatch(r"Hit 3NOSUCHHIT does not exist\. \(\d{13}\)", message)
    assert exc.value.response["ResponseMetadata"]["RequestId"]


def test_another_requesters_hit_does_not_exist_for_you(market_url: str, mturk: MTurk) -> None:
    hit = create_hit(mturk)
    other = make_client(market_url, key=OTHER_REQUESTER)
    with pytest.raises(other.exceptions.RequestError):
        other.get_hit(HITId=hit["HITId"])
    assert other.list_hits()["NumResults"] == 0


def test_service_faults_are_http_500_and_retried_by_botocore(market_url: str, mturk: MTurk) -> None:
    from backend.market.protocol import inject_faults

    inject_faults("GetAccountBalance", 1)
    with pytest.raises(mturk.exceptions.ServiceFault) as exc:
        mturk.get_account_balance()
    assert exc.value.response["ResponseMetadata"]["HTTPStatusCode"] == 500
    inject_faults("GetAccountBalance", 2)
    patient = make_client(market_url, retries=3)
    result = patient.get_account_balance()
    assert result["ResponseMetadata"]["RetryAttempts"] == 2


def test_a_response_outside_its_output_shape_becomes_a_service_fault(
    mturk, monkeypatch: pytest.MonkeyPatch
) -> None:
    from backend.market import operations

    monkeypatch.setitem(operations.HANDLERS, "GetAccountBalance",
                        lambda call, params: {"AvailableBalance": 12})
    with pytest.raises(mturk.exceptions.ServiceFault) as exc:
        mturk.get_account_balance()
    assert "AvailableBalance must be a string" in error_of(exc)[2]


def test_the_endpoint_answers_with_and_without_a_trailing_slash(market_url: str) -> None:
    for path in ("/mturk", "/mturk/"):
        client = make_client(market_url, path=path)
        assert client.get_account_balance()["AvailableBalance"] == "10000.00"
