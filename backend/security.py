"""Passwords and signed tokens (HMAC-SHA256 over a JSON payload, with an expiry).

Tokens travel in URLs and headers, never in cookies: the annotation page runs inside a
sandboxed MTurk iframe where third-party cookies are blocked.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import os
import time
from typing import Any

from backend.errors import Unauthorized

_SCRYPT = {"n": 2**14, "r": 8, "p": 1, "dklen": 32}


def hash_password(password: str) -> str:
    salt = os.urandom(16)
    digest = hashlib.scrypt(password.encode(), salt=salt, **_SCRYPT)
    return f"scrypt${salt.hex()}${digest.hex()}"


def verify_password(password: str, stored: str) -> bool:
    try:
        scheme, salt_hex, digest_hex = stored.split("$")
    except ValueError:
        return False
    if scheme != "scrypt":
        return False
    digest = hashlib.scrypt(password.encode(), salt=bytes.fromhex(salt_hex), **_SCRYPT)
    return hmac.compare_digest(digest.hex(), digest_hex)


def _b64(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode()


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


def sign_token(payload: dict[str, Any], secret: str, ttl_s: int) -> str:
    """A URL-safe token carrying ``payload`` until ``ttl_s`` seconds from now."""
    body = dict(payload, exp=int(time.time()) + ttl_s)
    raw = _b64(json.dumps(body, separators=(",", ":"), sort_keys=True).encode())
    sig = hmac.new(secret.encode(), raw.encode(), hashlib.sha256).digest()
    return f"{raw}.{_b64(sig)}"


def verify_token(token: str, secret: str, scope: str | tuple[str, ...]) -> dict[str, Any]:
    """The payload of a valid, unexpired token of ``scope`` (or of one of several scopes);
    Unauthorized otherwise."""
    try:
        raw, sig = token.split(".")
        expected = hmac.new(secret.encode(), raw.encode(), hashlib.sha256).digest()
        if not hmac.compare_digest(expected, _unb64(sig)):
            raise ValueError
        payload = json.loads(_unb64(raw))
    except (ValueError, json.JSONDecodeError):
        raise Unauthorized("token is malformed or its signature does not match") from None
    scopes = (scope,) if isinstance(scope, str) else scope
    if payload.get("scope") not in scopes:
        raise Unauthorized(f"token is not valid for {' or '.join(scopes)}")
    if payload.get("exp", 0) < time.time():
        raise Unauthorized("token has expired")
    return payload
