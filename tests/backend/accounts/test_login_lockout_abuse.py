"""A stranger cannot lock a real user out, while guessing stays limited: failures lock the
account for the guessing address only; a guesser spread over many addresses closes the account
to new addresses within MAX_ACCOUNT_FAILURES guesses, while the owner's known addresses keep
signing in; behind DEXLABEL_TRUSTED_PROXIES the forwarded client address is counted, and a
forged X-Forwarded-For from any other peer is ignored."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from backend.accounts import limits
from backend.config import Settings
from tests.backend.conftest import ADMIN_EMAIL, ADMIN_PASSWORD
from tests.conftest import reset_caches


def _at(client: TestClient, address: str) -> TestClient:
    """A client of the same app (and so the same limiter) connecting from ``address``."""
    return TestClient(client.app, client=(address, 40000))


def _login(client: TestClient, password: str, headers: dict | None = None) -> int:
    resp = client.post("/api/auth/token", json={"email": ADMIN_EMAIL, "password": password},
                       headers=headers or {})
    if resp.status_code == 429:
        assert int(resp.headers["Retry-After"]) > 0
    return resp.status_code


def test_a_guesser_at_one_address_does_not_lock_the_owner_out_elsewhere(
    client: TestClient, admin_headers: dict
) -> None:
    attacker, owner = _at(client, "203.0.113.7"), _at(client, "198.51.100.20")
    allowed = limits.MAX_ACCOUNT_ADDRESS_FAILURES
    codes = [_login(attacker, f"guess {i}") for i in range(limits.MAX_ADDRESS_FAILURES + 5)]
    assert codes[:allowed] == [401] * allowed
    assert set(codes[allowed:]) == {429}
    assert _login(attacker, ADMIN_PASSWORD) == 429, "the guessing address stays locked"
    # The owner, at an address that never signed in before, is not held.
    assert _login(owner, ADMIN_PASSWORD) == 200


def test_a_distributed_guesser_is_stopped_and_known_addresses_still_sign_in(
    client: TestClient, admin_headers: dict
) -> None:
    owner = _at(client, "198.51.100.20")
    assert _login(owner, ADMIN_PASSWORD) == 200  # the owner's address is now known
    tried = 0
    for i in range(limits.MAX_ACCOUNT_FAILURES + 20):
        bot = _at(client, f"10.{i // 250}.{i % 250}.9")
        code = _login(bot, f"guess {i}")
        if code == 429:
            break
        assert code == 401
        tried += 1
    assert tried == limits.MAX_ACCOUNT_FAILURES, "guesses let through from many addresses"
    # A new address is refused even with the right password, for the account-wide window.
    fresh = _at(client, "192.0.2.77")
    resp = fresh.post("/api/auth/token", json={"email": ADMIN_EMAIL, "password": ADMIN_PASSWORD})
    assert resp.status_code == 429
    assert "addresses it has not signed in from" in resp.json()["detail"]
    assert limits.WINDOW_S < int(resp.headers["Retry-After"]) <= limits.ACCOUNT_WINDOW_S
    # The owner's known address is not held by the account-wide limit.
    assert _login(owner, ADMIN_PASSWORD) == 200
    # Another account is not affected at all.
    other = fresh.post("/api/auth/token", json={"email": "x@example.org", "password": "y"})
    assert other.status_code == 401


@pytest.fixture
def behind_proxy(monkeypatch: pytest.MonkeyPatch, app_env: dict) -> None:
    monkeypatch.setenv("DEXLABEL_TRUSTED_PROXIES", '["10.9.0.0/24", "127.0.0.1"]')
    reset_caches()


def test_a_trusted_proxy_forwards_the_client_address(
    behind_proxy: None, client: TestClient, admin_headers: dict
) -> None:
    proxy = _at(client, "10.9.0.3")
    for i in range(limits.MAX_ACCOUNT_ADDRESS_FAILURES):
        # The left-most hop is the client's own claim; the right-most untrusted one counts.
        hdr = {"X-Forwarded-For": f"1.1.1.{i}, 203.0.113.7, 127.0.0.1"}
        assert _login(proxy, "wrong", hdr) == 401
    hdr = {"X-Forwarded-For": "203.0.113.7"}
    assert _login(proxy, ADMIN_PASSWORD, hdr) == 429, "the forwarded address is counted"
    # Another client behind the same proxy is not held.
    assert _login(proxy, ADMIN_PASSWORD, {"X-Forwarded-For": "198.51.100.20"}) == 200


def test_a_forged_forwarded_for_from_an_untrusted_peer_is_ignored(
    behind_proxy: None, client: TestClient, admin_headers: dict
) -> None:
    direct = _at(client, "203.0.113.7")
    for i in range(limits.MAX_ACCOUNT_ADDRESS_FAILURES):
        # Each attempt claims another address: none is believed.
        assert _login(direct, "wrong", {"X-Forwarded-For": f"192.0.2.{i}"}) == 401
    assert _login(direct, ADMIN_PASSWORD, {"X-Forwarded-For": "198.51.100.1"}) == 429


def test_trusted_proxies_refuse_what_is_not_an_address(monkeypatch: pytest.MonkeyPatch) -> None:
    assert Settings(trusted_proxies="10.0.0.0/8, ::1").trusted_proxies == ["10.0.0.0/8", "::1/128"]
    monkeypatch.setenv("DEXLABEL_TRUSTED_PROXIES", "10.0.0.0/8,proxy.example")
    with pytest.raises(ValueError, match=r"'proxy\.example' is not an IP address"):
        Settings()
