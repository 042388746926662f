"""Passwords and signed tokens (HMAC-SHA256 over a JSON payload, with an expiry).

Tokens travel in headers, never in cookies: the annotation page runs inside a sandboxed MTurk
iframe where third-party cookies are blocked. Only short-lived read-only view tokens go into
URLs (frame links).

Passwords are hashed with scrypt. Each hash takes tens of milliseconds of CPU, so at most
``SCRYPT_SLOTS`` run at once in a process: concurrent password guesses queue among themselves
instead of taking every core from the other requests. A login for an account that does not
exist is checked against a dummy hash, so it takes as long as one for an account that does.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import hmac
import json
import os
import secrets
import threading
import time
import weakref
from typing import Any

import anyio.to_thread
from anyio import CapacityLimiter

from backend.errors import Unauthorized

_SCRYPT = {"n": 2**14, "r": 8, "p": 1, "dklen": 32}
# scrypt computations running at once in this process (half the cores, at most 2): a burst of
# logins waits for a slot rather than starving every other request of CPU.
SCRYPT_SLOTS = max(1, min(2, (os.cpu_count() or 1) // 2))
_scrypt_slots = threading.BoundedSemaphore(SCRYPT_SLOTS)
_dummy_lock = threading.Lock()
_dummy_hash: str | None = None
# Per event loop: the thread slots of password checks awaited by async endpoints (logins), so
# the requests waiting for a slot hold no thread of the server's pool while they wait.
_loop_slots: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, CapacityLimiter] = (
    weakref.WeakKeyDictionary())


def _scrypt(password: str, salt: bytes) -> bytes:
    with _scrypt_slots:
        return hashlib.scrypt(password.encode(), salt=salt, **_SCRYPT)


def hash_password(password: str) -> str:
    salt = os.urandom(16)
    return f"scrypt${salt.hex()}${_scrypt(password, salt).hex()}"


def dummy_hash() -> str:
    """A scrypt hash of a random password nobody knows (made once per process)."""
    global _dummy_hash
    with _dummy_lock:
        if _dummy_hash is None:
            _dummy_hash = hash_password(secrets.token_hex(16))
        return _dummy_hash


def verify_password(password: str, stored: str | None) -> bool:
    """Whether ``password`` matches ``stored``. ``None`` (no such account) is checked against a
    dummy hash and is always False, in the same time as a real check."""
    candidate = dummy_hash() if stored is None else stored
    try:
        scheme, salt_hex, digest_hex = candidate.split("$")
        salt = bytes.fromhex(salt_hex)
    except ValueError:
        scheme, salt, digest_hex = "", b"", ""
    if scheme != "scrypt":
        # A malformed stored hash still costs one scrypt, so it cannot be told apart either.
        _scrypt(password, b"\0" * 16)
        return False
    match = hmac.compare_digest(_scrypt(password, salt).hex(), digest_hex)
    return match and stored is not None


async def check_password(password: str, stored: str | None) -> bool:
    """``verify_password`` for async endpoints: it waits for one of ``SCRYPT_SLOTS`` threads
    of its own, so a queue of password checks never occupies the server's request threads."""
    loop = asyncio.get_running_loop()
    slots = _loop_slots.get(loop)
    if slots is None:
        slots = _loop_slots[loop] = CapacityLimiter(SCRYPT_SLOTS)
    return await anyio.to_thread.run_sync(verify_password, password, stored, limiter=slots)


def _b64(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode()


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


def sign_token(payload: dict[str, Any], secret: str, ttl_s: int) -> str:
    """A URL-safe token carrying ``payload`` until ``ttl_s`` seconds from now."""
    if not secret:
        raise ValueError("no signing key: tokens are signed with Settings.signing_key")
    body = dict(payload, exp=int(time.time()) + ttl_s)
    raw = _b64(json.dumps(body, separators=(",", ":"), sort_keys=True).encode())
    sig = hmac.new(secret.encode(), raw.encode(), hashlib.sha256).digest()
    return f"{raw}.{_b64(sig)}"


def verify_token(token: str, secret: str, scope: str | tuple[str, ...]) -> dict[str, Any]:
    """The payload of a valid, unexpired token of ``scope`` (or of one of several scopes);
    Unauthorized otherwise."""
    if not secret:
        raise ValueError("no signing key: tokens are checked with Settings.signing_key")
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
