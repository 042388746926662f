"""Helpers of the marketplace tests: clients, HIT fixtures and the worker's side of a HIT."""

from __future__ import annotations

import json
from typing import Any

import boto3
import httpx
from botocore.auth import SigV4Auth
from botocore.awsrequest import AWSRequest
from botocore.config import Config
from botocore.credentials import Credentials

REQUESTER = ("AKIAMARKETTESTONE000", "market-test-secret-one")
OTHER_REQUESTER = ("AKIAMARKETTESTTWO000", "market-test-secret-two")
POOR_REQUESTER = ("AKIAMARKETTESTPOOR00", "market-test-secret-poor")
POOR_BALANCE = "1.00"
REQUESTERS_SETTING = ",".join([
    ":".join(REQUESTER), ":".join(OTHER_REQUESTER), ":".join(POOR_REQUESTER) + ":" + POOR_BALANCE])
START_BALANCE = "10000.00"
TARGET_PREFIX = "MTurkRequesterServiceV20170117."
WORKER = "A1WORKERONE"
WORKER_2 = "A2WORKERTWO"
WORKER_3 = "A3WORKERTHREE"
ANSWERS_NS = ("http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/2005-10-01/"
              "QuestionFormAnswers.xsd")

# boto3 builds the mturk client class at run time; there is no class to import for annotations.
MTurk = Any

# One session for every client: botocore loads the mturk model once.
_SESSION = boto3.session.Session()


def make_client(
    base: str, key: tuple[str, str] = REQUESTER, retries: int = 1, path: str = "/mturk"
) -> MTurk:
    config = Config(retries={"total_max_attempts": retries, "mode": "standard"})
    return _SESSION.client("mturk", endpoint_url=base + path, region_name="us-east-1",
                           aws_access_key_id=key[0], aws_secret_access_key=key[1],
                           config=config)


def external_question(url: str = "https://annotate.example.org/task?t=1", height: int = 800) -> str:
    return ('<ExternalQuestion xmlns="http://mechanicalturk.amazonaws.com/'
            'AWSMechanicalTurkDataSchemas/2006-07-14/ExternalQuestion.xsd">'
            f"<ExternalURL>{url}</ExternalURL><FrameHeight>{height}</FrameHeight>"
            "</ExternalQuestion>")


def hit_params(**overrides: Any) -> dict[str, Any]:
    params: dict[str, Any] = {
        "Title": "Track 21 hand joints", "Description": "Click each joint through the clip",
        "Keywords": "hand, keypoints", "Reward": "0.50", "MaxAssignments": 1,
        "LifetimeInSeconds": 3600, "AssignmentDurationInSeconds": 600,
        "AutoApprovalDelayInSeconds": 86400, "Question": external_question(),
    }
    params.update(overrides)
    return params


def create_hit(client: MTurk, **overrides: Any) -> dict[str, Any]:
    return client.create_hit(**hit_params(**overrides))["HIT"]


def accept(hit_id: str, worker_id: str = WORKER) -> str:
    """The worker accepts the HIT through the worker-side service; its AssignmentId."""
    from backend.db import session_scope
    from backend.market import clock, workers

    with session_scope() as session:
        return workers.accept(session, worker_id, hit_id, clock.now()).assignment_id


def submit(base: str, assignment_id: str, **fields: str) -> httpx.Response:
    """The annotation page's form post to externalSubmit."""
    data = {"assignmentId": assignment_id, **fields}
    return httpx.post(f"{base}/mturk/externalSubmit", data=data, timeout=10)


def work(base: str, hit_id: str, worker_id: str = WORKER, **fields: str) -> str:
    """Accept and submit one assignment; its AssignmentId."""
    assignment_id = accept(hit_id, worker_id)
    resp = submit(base, assignment_id, **(fields or {"labels": "ok"}))
    assert resp.status_code == 200, resp.text
    return assignment_id


def signed_post(
    base: str, operation: str, body: Any, key: tuple[str, str] = REQUESTER,
    headers: dict[str, str] | None = None, raw: bytes | None = None,
) -> httpx.Response:
    """A request signed with botocore's SigV4 signer but built by hand, so it can carry what
    the boto3 client would refuse to send."""
    payload = raw if raw is not None else json.dumps(body).encode()
    request = AWSRequest(method="POST", url=f"{base}/mturk", data=payload, headers={
        "X-Amz-Target": TARGET_PREFIX + operation,
        "Content-Type": "application/x-amz-json-1.1", **(headers or {})})
    SigV4Auth(Credentials(*key), "mturk-requester", "us-east-1").add_auth(request)
    return httpx.post(request.url, content=payload, headers=dict(request.headers.items()),
                      timeout=10)


def error_of(exc_info: Any) -> tuple[str, str, str]:
    """(Error.Code, TurkErrorCode, Message) of a ClientError."""
    response = exc_info.value.response
    error = response["Error"]
    return error["Code"], response.get("TurkErrorCode", ""), error["Message"]
