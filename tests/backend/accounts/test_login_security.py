"""Logins and bearer tokens: failed logins are limited per account and per client address
(429 with Retry-After, the right password included, until the window has passed); an
unknown email takes as long to refuse as a known one; password checks queue on their own
threads; logout and a password change or reset end every token issued before."""

from __future__ import annotations

import asyncio
import statistics
import threading
import time
from collections.abc import Callable

import pytest
from fastapi.testclient import TestClient

from backend.accounts import limits
from backend.db import session_scope
from tests.backend.conftest import ADMIN_EMAIL, ADMIN_PASSWORD
from tests.servers import run_async

WORKER_EMAIL = "worker@example.org"
WORKER_PASSWORD = "worker password 1"


def _login(client: TestClient, email: str, password: str, path: str = "/api/auth/token"):
    return client.post(path, json={"email": email, "password": password})


def _move_clock(monkeypatch: pytest.MonkeyPatch, by_s: float) -> None:
    monkeypatch.setattr(limits, "now", lambda: time.time() + by_s)


def _new_worker(client: TestClient, admin_headers: dict) -> None:
    resp = client.post("/api/portal/workers", headers=admin_headers,
                       json={"email": WORKER_EMAIL, "password": WORKER_PASSWORD})
    assert resp.status_code == 200, resp.text


@pytest.mark.parametrize("path", ["/api/auth/token", "/api/portal/login"])
def test_failed_logins_lock_the_account_until_the_window_passes(
    client: TestClient, admin_headers: dict, monkeypatch: pytest.MonkeyPatch, path: str
) -> None:
    _new_worker(client, admin_headers)
    email, password = ((ADMIN_EMAIL, ADMIN_PASSWORD) if path == "/api/auth/token"
                       else (WORKER_EMAIL, WORKER_PASSWORD))
    for _ in range(limits.MAX_ACCOUNT_ADDRESS_FAILURES):
        assert _login(client, email, "wrong password", path).status_code == 401
    locked = _login(client, email, "wrong password", path)
    assert locked.status_code == 429, locked.text
    assert "too many failed logins for this account" in locked.json()["detail"]
    retry_after = int(locked.headers["Retry-After"])
    assert 0 < retry_after <= limits.WINDOW_S
    right = _login(client, email.upper(), password, path)  # the same account, other spelling
    assert right.status_code == 429, "the right password is refused during the lockout too"
    # Another account from the same address is not locked (the address has failures to spare).
    assert _login(client, "someone-else@example.org", "x", path).status_code == 401

    _move_clock(monkeypatch, retry_after - 5)
    assert _login(client, email, password, path).status_code == 429
    _move_clock(monkeypatch, retry_after + 1)
    assert _login(client, email, password, path).status_code == 200
    # A success forgets the account's failures: a typo afterwards is a plain 401.
    assert _login(client, email, "wrong password", path).status_code == 401
    assert _login(client, email, password, path).status_code == 200


def test_failed_logins_from_one_address_lock_the_address(
    client: TestClient, admin_headers: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    for i in range(limits.MAX_ADDRESS_FAILURES):
        path = "/api/auth/token" if i % 2 else "/api/portal/login"
        assert _login(client, f"guess{i}@example.org", "password", path).status_code == 401
    locked = _login(client, ADMIN_EMAIL, ADMIN_PASSWORD)
    assert locked.status_code == 429 and "this address" in locked.json()["detail"]
    assert int(locked.headers["Retry-After"]) > 0
    _move_clock(monkeypatch, limits.WINDOW_S + 1)
    assert _login(client, ADMIN_EMAIL, ADMIN_PASSWORD).status_code == 200


@pytest.mark.parametrize("path", ["/api/auth/token", "/api/portal/login"])
def test_an_unknown_email_takes_as_long_as_a_known_one(
    client: TestClient, admin_headers: dict, monkeypatch: pytest.MonkeyPatch, path: str
) -> None:
    _new_worker(client, admin_headers)
    monkeypatch.setattr(limits, "MAX_ACCOUNT_FAILURES", 1000)
    monkeypatch.setattr(limits, "MAX_ACCOUNT_ADDRESS_FAILURES", 1000)
    monkeypatch.setattr(limits, "MAX_ADDRESS_FAILURES", 1000)
    known = ADMIN_EMAIL if path == "/api/auth/token" else WORKER_EMAIL

    def timed(email: str) -> float:
        start = time.perf_counter()
        resp = _login(client, email, "wrong password", path)
        elapsed = time.perf_counter() - start
        assert resp.status_code == 401 and resp.json()["detail"] == "email or password is wrong"
        return elapsed

    timed(known), timed("warm-up@example.org")
    # Taken in turn, so that both see the same load of a shared machine.
    known_s, unknown_s = [], []
    for i in range(12):
        known_s.append(timed(known))
        unknown_s.append(timed(f"nobody{i}@example.org"))
    ratio = statistics.median(known_s) / statistics.median(unknown_s)
    assert 0.5 < ratio < 2, (known_s, unknown_s)


def test_password_checks_run_on_their_own_few_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    """Twenty concurrent logins' password checks: at most SCRYPT_SLOTS at once, and none of
    them holds a thread of the server's request pool while it waits."""
    import anyio.to_thread

    from backend import security

    running, peak, lock = 0, 0, threading.Lock()
    real: Callable[..., bytes] = security.hashlib.scrypt

    def counting_scrypt(*args, **kwargs) -> bytes:
        nonlocal running, peak
        with lock:
            running += 1
            peak = max(peak, running)
        try:
            time.sleep(0.02)
            return real(*args, **kwargs)
        finally:
            with lock:
                running -= 1

    stored = security.hash_password("a long password")
    monkeypatch.setattr(security.hashlib, "scrypt", counting_scrypt)

    async def main() -> tuple[list[bool], float]:
        pool = anyio.to_thread.current_default_thread_limiter()
        busy = 0.0

        async def watch() -> None:
            nonlocal busy
            for _ in range(20):
                busy = max(busy, pool.borrowed_tokens)
                await asyncio.sleep(0.01)

        watcher = asyncio.create_task(watch())
        results = await asyncio.gather(*(security.check_password(p, stored) for p in
                                         ["a long password"] + ["wrong"] * 19))
        await watcher
        return list(results), busy

    results, busy = run_async(main)
    assert results == [True] + [False] * 19
    assert peak <= security.SCRYPT_SLOTS
    assert busy == 0, "waiting password checks held threads of the request pool"


def test_the_redis_store_counts_and_clears_failures(
    redis_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    limiter = limits.LoginLimiter(limits.RedisStore(redis_url, f"instance-{time.time()}"))
    lock = limiter.limits("admin", "a@example.org", "10.0.0.1")
    for _ in range(limits.MAX_ACCOUNT_ADDRESS_FAILURES):
        limiter.check(lock)
        limiter.failed(lock)
    with pytest.raises(limits.TooManyAttempts) as refused:
        limiter.check(lock)
    assert int(refused.value.headers["Retry-After"]) > 0
    other = limiter.limits("admin", "b@example.org", "10.0.0.2")
    limiter.check(other)  # another account from another address is not locked
    _move_clock(monkeypatch, limits.WINDOW_S + 1)
    limiter.check(lock)
    limiter.succeeded(lock)
    assert limiter.store.recent(lock[0].key, 0) == []


def _me(client: TestClient, headers: dict) -> int:
    return client.get("/api/auth/me", headers=headers).status_code


def test_logout_ends_every_admin_token(client: TestClient, admin_headers: dict) -> None:
    second = _login(client, ADMIN_EMAIL, ADMIN_PASSWORD).json()["access_token"]
    assert _me(client, admin_headers) == 200
    assert client.post("/api/auth/logout", headers=admin_headers).status_code == 204
    assert _me(client, admin_headers) == 401
    refused = client.get("/api/auth/me", headers={"Authorization": f"Bearer {second}"})
    assert refused.status_code == 401 and "signed out" in refused.json()["detail"]
    again = _login(client, ADMIN_EMAIL, ADMIN_PASSWORD).json()["access_token"]
    assert _me(client, {"Authorization": f"Bearer {again}"}) == 200


def test_a_password_change_or_reset_ends_every_admin_token(
    client: TestClient, admin_headers: dict
) -> None:
    from backend.accounts.service import create_admin

    wrong = client.post("/api/auth/password", headers=admin_headers,
                        json={"current_password": "not it", "new_password": "a new password 1"})
    assert wrong.status_code == 401 and _me(client, admin_headers) == 200
    changed = client.post("/api/auth/password", headers=admin_headers,
                          json={"current_password": ADMIN_PASSWORD,
                                "new_password": "a new password 1"})
    assert changed.status_code == 200, changed.text
    assert _me(client, admin_headers) == 401
    fresh = {"Authorization": f"Bearer {changed.json()['access_token']}"}
    assert _me(client, fresh) == 200
    assert _login(client, ADMIN_EMAIL, ADMIN_PASSWORD).status_code == 401
    with session_scope() as session:  # `dexlabel create-admin EMAIL --reset`
        create_admin(session, ADMIN_EMAIL, "a reset password", reset=True)
    assert _me(client, fresh) == 401
    assert _login(client, ADMIN_EMAIL, "a reset password").status_code == 200


def test_logout_and_password_change_end_every_portal_token(
    client: TestClient, admin_headers: dict
) -> None:
    _new_worker(client, admin_headers)

    def token() -> dict:
        resp = _login(client, WORKER_EMAIL, WORKER_PASSWORD, "/api/portal/login")
        assert resp.status_code == 200, resp.text
        return {"Authorization": f"Bearer {resp.json()['access_token']}"}

    first, second = token(), token()
    assert client.get("/api/portal/me", headers=first).status_code == 200
    assert client.post("/api/portal/logout", headers=first).status_code == 204
    assert client.get("/api/portal/me", headers=first).status_code == 401
    assert client.get("/api/portal/me", headers=second).status_code == 401
    third = token()
    changed = client.post("/api/portal/password", headers=third,
                          json={"current_password": WORKER_PASSWORD,
                                "new_password": "worker password 2"})
    assert changed.status_code == 200, changed.text
    assert client.get("/api/portal/me", headers=third).status_code == 401
    fresh = {"Authorization": f"Bearer {changed.json()['access_token']}"}
    assert client.get("/api/portal/me", headers=fresh).status_code == 200
