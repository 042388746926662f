"""Worker accounts: admin-created, invited, password login, and tokens kept to their scope."""

from __future__ import annotations

import re

import httpx
from sqlalchemy import select

from backend.db import session_scope
from backend.market import clock
from backend.market.models import Worker
from tests.backend.portal.conftest import WORKER_PASSWORD, Portal


def test_admin_created_worker_logs_in_as_a_new_marketplace_worker(portal: Portal) -> None:
    login = portal.new_worker("Ann@Example.org")
    assert re.fullmatch(r"A[A-Z0-9]{13}", login["worker_id"])
    me = portal.ok("GET", "/me", login["access_token"])
    assert me["email"] == "ann@example.org" and me["worker_id"] == login["worker_id"]
    with session_scope() as session:
        ids = session.scalars(select(Worker.worker_id)).all()
    assert login["worker_id"] in ids


def test_creating_a_worker_needs_an_admin(portal: Portal) -> None:
    body = {"email": "bob@example.org", "password": WORKER_PASSWORD}
    assert portal.call("POST", "/workers", json=body).status_code == 401
    worker = portal.new_worker("carl@example.org")
    resp = portal.call("POST", "/workers", worker["access_token"], json=body)
    assert resp.status_code == 401 and "admin" in resp.json()["detail"]


def test_account_rules_name_what_is_wrong(portal: Portal) -> None:
    portal.new_worker("dora@example.org")
    again = httpx.post(f"{portal.base}/api/portal/workers", headers=portal.admin_headers,
                       json={"email": "dora@example.org", "password": WORKER_PASSWORD})
    assert again.status_code == 409
    short = httpx.post(f"{portal.base}/api/portal/workers", headers=portal.admin_headers,
                       json={"email": "eve@example.org", "password": "short"})
    assert short.status_code == 400 and "password" in short.json()["detail"]
    wrong = portal.call("POST", "/login", json={"email": "dora@example.org", "password": "nope"})
    assert wrong.status_code == 401


def test_invite_registers_one_account_once(portal: Portal) -> None:
    invite = httpx.post(f"{portal.base}/api/portal/invites", headers=portal.admin_headers,
                        json={}).json()
    # The token rides in the fragment, which browsers never send to a server or a log.
    assert invite["url"].endswith(f"/market/#invite={invite['invite']}")
    assert "?" not in invite["url"]
    body = {"invite": invite["invite"], "email": "fay@example.org", "password": WORKER_PASSWORD}
    account = portal.ok("POST", "/register", json=body)
    login = portal.ok("POST", "/login", json={"email": "fay@example.org",
                                              "password": WORKER_PASSWORD})
    assert login["worker_id"] == account["worker_id"]
    reused = portal.call("POST", "/register", json={**body, "email": "gus@example.org"})
    assert reused.status_code == 409 and "already used" in reused.json()["detail"]
    unknown = portal.call("POST", "/register", json={**body, "invite": "not-an-invite-token"})
    assert unknown.status_code == 404


def test_expired_invite_is_refused(portal: Portal) -> None:
    invite = httpx.post(f"{portal.base}/api/portal/invites", headers=portal.admin_headers,
                        json={"ttl_hours": 1}).json()
    clock.advance(3601)
    resp = portal.call("POST", "/register", json={
        "invite": invite["invite"], "email": "hal@example.org", "password": WORKER_PASSWORD})
    assert resp.status_code == 409 and "expired" in resp.json()["detail"]


def test_portal_and_admin_tokens_each_open_only_their_own_api(portal: Portal) -> None:
    worker = portal.new_worker("ivy@example.org")
    admin_token = portal.admin_headers["Authorization"].split()[1]
    refused = portal.call("GET", "/hits", admin_token)
    assert refused.status_code == 401 and "portal" in refused.json()["detail"]
    assert portal.call("GET", "/hits").status_code == 401
    admin_api = httpx.get(f"{portal.base}/api/tasks", timeout=10,
                          headers={"Authorization": f"Bearer {worker['access_token']}"})
    assert admin_api.status_code == 401
    tampered = worker["access_token"][:-2] + ("AA" if worker["access_token"][-2:] != "AA" else "BB")
    assert portal.call("GET", "/me", tampered).status_code == 401
