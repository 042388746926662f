"""The worker portal in Chromium with a team task: the member it is assigned to sees it marked
"assigned to you" and can open it; another member's list does not show it. The task is
published by the team provider, in this process, on the live server's built-in marketplace."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from backend.crowd.provider import CrowdProvider, Requirements, UnitSpec
from tests.browser.conftest import LiveServer
from tests.conftest import reset_caches

PASSWORD = "team member password"


@pytest.fixture
def team(live_server: LiveServer, monkeypatch: pytest.MonkeyPatch) -> Iterator[CrowdProvider]:
    """The team provider on the live server's settings (its database and address)."""
    from backend.config import get_settings
    from backend.crowd.providers.team import make

    for key, value in live_server.env.items():
        monkeypatch.setenv(key, value)
    reset_caches()
    yield make(get_settings())
    reset_caches()


def _member(server: LiveServer, email: str) -> str:
    made = server.admin("POST", "/api/portal/workers", {"email": email, "password": PASSWORD})
    assert isinstance(made, dict)
    return str(made["worker_id"])


def _sign_in(page: Page, server: LiveServer, email: str) -> None:
    page.goto(f"{server.base}/market/")
    page.locator("#login input[name=email]").fill(email)
    page.locator("#login input[name=password]").fill(PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#hits-view")).to_be_visible()


def test_a_team_task_is_marked_for_its_assignee_and_hidden_from_the_others(
    live_server: LiveServer, team: CrowdProvider, browser, output_dir: Path
) -> None:
    server = live_server
    eve = _member(server, "team-eve@example.org")
    _member(server, "team-fay@example.org")
    task = server.task("hand")
    token = server.admin("POST", f"/api/tasks/{task['id']}/preview-token")["token"]
    unit = UnitSpec(
        key=f"dxteam-browser-{task['id']}", task_id=task["id"], title="Hand joints (team)",
        description="Click each hand joint.", keywords="hand",
        page_url=f"{server.base}/annotate/?task={token}", reward_cents=0, places=1,
        lifetime_s=3600, allotted_s=1800, auto_approve_s=86400, expected_s=600,
        frame_height=700, note=f"dexlabel task {task['id']} round 1",
        requirements=Requirements(assignee=eve))
    [published] = team.publish([unit])
    try:
        for email, seen in (("team-eve@example.org", True), ("team-fay@example.org", False)):
            ctx = browser.new_context(viewport={"width": 1366, "height": 900})
            page = ctx.new_page()
            _sign_in(page, server, email)  # the list is drawn before its view is shown
            row = page.locator(f'tr[data-hit="{published.unit_id}"]')
            if seen:
                expect(row.locator(".mark-assigned")).to_have_text("assigned to you")
                expect(row.locator(".facts")).to_contain_text("hand")
                page.screenshot(path=str(output_dir / "portal_team_assigned.png"))
                row.locator("a.hit-title").click()
                expect(page.locator("#accept")).to_be_enabled()
            else:
                expect(row).to_have_count(0)
            ctx.close()
    finally:
        team.close(published.unit_id)
