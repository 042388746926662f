"""AWS Signature Version 4 on requester calls, checked against the configured key pairs.

The canonical request is rebuilt from what arrived (method, raw path, raw query, the headers
the client listed as signed, SHA-256 of the body) exactly as the SigV4 specification and
botocore build it, then signed with the requester's secret and compared in constant time.
Failures answer with the generic AWS JSON-protocol error types MTurk's front end used.
"""

from __future__ import annotations

import hashlib
import hmac
import posixpath
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from urllib.parse import quote

from backend.config import MarketRequester
from backend.market.errors import ProtocolError

ALGORITHM = "AWS4-HMAC-SHA256"
SERVICE = "mturk-requester"
TERMINATOR = "aws4_request"
AMZ_DATE_FORMAT = "%Y%m%dT%H%M%SZ"
# AWS accepts requests whose signing time is within 15 minutes of its own clock.
MAX_CLOCK_SKEW = timedelta(minutes=15)
UNSIGNED_PAYLOAD = "UNSIGNED-PAYLOAD"


@dataclass(frozen=True)
class SignedRequest:
    method: str
    raw_path: str
    raw_query: str
    headers: list[tuple[str, str]]  # names lower-cased, in arrival order
    body: bytes

    def header(self, name: str) -> str | None:
        values = [value for key, value in self.headers if key == name]
        return ",".join(values) if values else None


@dataclass(frozen=True)
class _Authorization:
    access_key: str
    date: str
    region: str
    service: str
    terminator: str
    signed_headers: list[str]
    signature: str


def _incomplete(message: str) -> ProtocolError:
    return ProtocolError("IncompleteSignatureException", message)


def _bad_signature(message: str) -> ProtocolError:
    return ProtocolError("InvalidSignatureException", message)


def _parse_authorization(header: str | None) -> _Authorization:
    if not header:
        raise ProtocolError("MissingAuthenticationTokenException",
                            "The request has no Authorization header; sign requests with AWS "
                            "Signature Version 4.")
    algorithm, _, rest = header.strip().partition(" ")
    if algorithm != ALGORITHM:
        raise _incomplete(f"Authorization must use {ALGORITHM}, got {algorithm!r}.")
    parts = dict(item.strip().partition("=")[::2] for item in rest.split(","))
    missing = [key for key in ("Credential", "SignedHeaders", "Signature") if not parts.get(key)]
    if missing:
        raise _incomplete(f"Authorization header lacks {', '.join(missing)}.")
    scope = parts["Credential"].split("/")
    if len(scope) != 5:
        raise _incomplete("Credential must be ACCESS_KEY/DATE/REGION/SERVICE/aws4_request.")
    access_key, date, region, service, terminator = scope
    return _Authorization(access_key, date, region, service, terminator,
                          signed_headers=parts["SignedHeaders"].split(";"),
                          signature=parts["Signature"])


def _signing_time(request: SignedRequest, auth: _Authorization, wall_now: datetime) -> str:
    stamp = request.header("x-amz-date")
    if stamp is None:
        raise _incomplete("The request has no X-Amz-Date header.")
    try:
        signed_at = datetime.strptime(stamp, AMZ_DATE_FORMAT).replace(tzinfo=UTC)
    except ValueError:
        raise _incomplete(f"X-Amz-Date {stamp!r} is not of the form 20170117T120000Z.") from None
    if abs(wall_now - signed_at) > MAX_CLOCK_SKEW:
        raise _bad_signature(f"Signature expired: signed at {stamp}, server time is "
                             f"{wall_now.strftime(AMZ_DATE_FORMAT)} (allowed skew 15 min).")
    if auth.date != stamp[:8]:
        raise _bad_signature(f"Credential date {auth.date} does not match X-Amz-Date {stamp}.")
    return stamp


def _canonical_path(raw_path: str) -> str:
    path = posixpath.normpath(raw_path) if raw_path else "/"
    if path.startswith("//"):
        path = "/" + path.lstrip("/")
    if raw_path.endswith("/") and not path.endswith("/"):
        path += "/"
    return quote(path, safe="/~")


def _canonical_query(raw_query: str) -> str:
    if not raw_query:
        return ""
    pairs = sorted(pair.partition("=")[::2] for pair in raw_query.split("&"))
    return "&".join(f"{key}={value}" for key, value in pairs)


def _canonical_request(request: SignedRequest, signed: list[str]) -> str:
    lines = []
    for name in signed:
        value = request.header(name)
        if value is None:
            raise _bad_signature(f"Signed header {name!r} is not in the request.")
        lines.append(f"{name}:{' '.join(value.split())}")
    body_hash = hashlib.sha256(request.body).hexdigest()
    claimed = request.header("x-amz-content-sha256")
    if claimed is not None and claimed != body_hash:
        raise _bad_signature("X-Amz-Content-SHA256 does not match the body; this service "
                             f"needs signed payloads, not {UNSIGNED_PAYLOAD}."
                             if claimed == UNSIGNED_PAYLOAD else
                             "X-Amz-Content-SHA256 does not match the body.")
    return "\n".join([
        request.method.upper(), _canonical_path(request.raw_path),
        _canonical_query(request.raw_query), "\n".join(lines) + "\n", ";".join(signed),
        claimed or body_hash,
    ])


def _hmac(key: bytes, message: str) -> bytes:
    return hmac.new(key, message.encode(), hashlib.sha256).digest()


def signature(secret: str, stamp: str, region: str, canonical_request: str) -> str:
    """The SigV4 signature of ``canonical_request`` (hex)."""
    scope = f"{stamp[:8]}/{region}/{SERVICE}/{TERMINATOR}"
    string_to_sign = "\n".join([
        ALGORITHM, stamp, scope, hashlib.sha256(canonical_request.encode()).hexdigest()])
    key = _hmac(f"AWS4{secret}".encode(), stamp[:8])
    for part in (region, SERVICE, TERMINATOR):
        key = _hmac(key, part)
    return hmac.new(key, string_to_sign.encode(), hashlib.sha256).hexdigest()


def authenticate(
    request: SignedRequest, requesters: dict[str, MarketRequester], wall_now: datetime
) -> MarketRequester:
    """The requester whose key signed ``request``; raises the AWS error for any failure."""
    auth = _parse_authorization(request.header("authorization"))
    requester = requesters.get(auth.access_key)
    if requester is None:
        raise ProtocolError("UnrecognizedClientException",
                            f"The access key {auth.access_key} is not a requester account of "
                            "this marketplace.")
    if auth.service != SERVICE or auth.terminator != TERMINATOR or not auth.region:
        raise _bad_signature(f"Credential must be scoped to REGION/{SERVICE}/{TERMINATOR}, got "
                             f"{auth.region}/{auth.service}/{auth.terminator}.")
    signed = sorted(name.strip().lower() for name in auth.signed_headers)
    for required in ("host", "x-amz-date"):
        if required not in signed:
            raise _incomplete(f"SignedHeaders must include {required}.")
    stamp = _signing_time(request, auth, wall_now)
    expected = signature(requester.secret_key, stamp, auth.region,
                         _canonical_request(request, signed))
    if not hmac.compare_digest(expected, auth.signature):
        raise _bad_signature(f"The request signature does not match the one computed with the "
                             f"secret key of {auth.access_key}; check the secret key and the "
                             "signing method.")
    return requester
