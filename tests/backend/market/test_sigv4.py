"""The SigV4 verifier against requests signed by botocore itself (no server involved)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from urllib.parse import urlsplit

import pytest
from botocore.auth import SigV4Auth
from botocore.awsrequest import AWSRequest
from botocore.credentials import Credentials

from backend.config import MarketRequester
from backend.market.auth import SignedRequest, authenticate
from backend.market.errors import ProtocolError

KEY = MarketRequester("AKIAUNITTESTKEY00000", "unit-test-secret-key", 0)


def _signed(url: str, body: bytes, secret: str = KEY.secret_key) -> SignedRequest:
    request = AWSRequest(method="POST", url=url, data=body, headers={
        "X-Amz-Target": "MTurkRequesterServiceV20170117.GetHIT",
        "Content-Type": "application/x-amz-json-1.1", "User-Agent": "unit  test"})
    SigV4Auth(Credentials(KEY.access_key, secret), "mturk-requester", "us-east-1").add_auth(request)
    parts = urlsplit(request.url)
    headers = [(name.lower(), value) for name, value in request.headers.items()]
    headers.append(("host", parts.netloc))
    return SignedRequest("POST", parts.path, parts.query, headers, body)


@pytest.mark.parametrize("url", [
    "http://127.0.0.1:8000/mturk", "http://127.0.0.1:8000/mturk/",
    "https://market.example.org/deep/./mturk", "http://h/mturk/a%20b?z=1&a=2&a=1",
])
def test_botocore_signatures_verify(url: str) -> None:
    request = _signed(url, b'{"HITId": "3ABC"}')
    assert authenticate(request, {KEY.access_key: KEY}, datetime.now(UTC)) is KEY


def test_a_changed_header_or_wrong_secret_does_not_verify() -> None:
    request = _signed("http://h/mturk", b"{}")
    changed = SignedRequest(request.method, request.raw_path, request.raw_query,
                            [(n, "MTurkRequesterServiceV20170117.DeleteHIT"
                              if n == "x-amz-target" else v) for n, v in request.headers],
                            request.body)
    for bad in (changed, _signed("http://h/mturk", b"{}", secret="another-secret")):
        with pytest.raises(ProtocolError) as exc:
            authenticate(bad, {KEY.access_key: KEY}, datetime.now(UTC))
        assert exc.value.wire_type == "InvalidSignatureException"


def test_clock_skew_beyond_fifteen_minutes_is_refused() -> None:
    request = _signed("http://h/mturk", b"{}")
    with pytest.raises(ProtocolError, match="Signature expired"):
        authenticate(request, {KEY.access_key: KEY}, datetime.now(UTC) + timedelta(minutes=16))
