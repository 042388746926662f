"""The admin page and the worker portal under their Content-Security-Policy: the answers
carry the policy (no framing, own scripts and styles only) and nosniff, the annotation page
stays frameable, and both pages load and work with no policy violation in the console."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest
from playwright.sync_api import ConsoleMessage, Page, expect

from tests.browser.conftest import ADMIN_EMAIL, ADMIN_PASSWORD, LiveServer

EMAIL, PASSWORD = "csp-worker@example.org", "csp worker password"


def test_the_pages_carry_the_policy_and_the_annotation_page_stays_frameable(
    live_server: LiveServer,
) -> None:
    for path in ("/admin/", "/market/", "/admin/app.js", "/market/style.css"):
        resp = httpx.get(f"{live_server.base}{path}", timeout=30)
        assert resp.status_code == 200, path
        policy = resp.headers.get("content-security-policy", "")
        assert "frame-ancestors 'none'" in policy, (path, policy)
        assert "script-src 'self'" in policy and "'unsafe-inline'" not in policy
        assert resp.headers.get("x-content-type-options") == "nosniff", path
    annotate = httpx.get(f"{live_server.base}/annotate/", timeout=30)
    assert annotate.status_code == 200
    assert "frame-ancestors" not in annotate.headers.get("content-security-policy", "")
    assert "x-frame-options" not in annotate.headers
    assert annotate.headers.get("x-content-type-options") == "nosniff"


@pytest.fixture
def watched_page(browser) -> Iterator[tuple[Page, list[str]]]:
    """A page and the policy violations and console errors it reports."""
    ctx = browser.new_context(viewport={"width": 1440, "height": 1000})
    ctx.set_default_timeout(15000)
    page = ctx.new_page()
    problems: list[str] = []

    def on_console(message: ConsoleMessage) -> None:
        if message.type == "error" or "Content Security Policy" in message.text:
            problems.append(message.text)

    page.on("console", on_console)
    page.on("pageerror", lambda exc: problems.append(str(exc)))
    # The event a document fires for each violation, also for those the console folds.
    page.add_init_script("""document.addEventListener('securitypolicyviolation', (e) =>
        console.error(`Content Security Policy violation: ${e.violatedDirective} `
                      + `${e.blockedURI}`));""")
    yield page, problems
    ctx.close()


def test_the_admin_page_works_under_its_policy(
    watched_page: tuple[Page, list[str]], live_server: LiveServer,
) -> None:
    page, problems = watched_page
    server = live_server
    page.goto(f"{server.base}/admin/")
    page.locator("#login input[name=email]").fill(ADMIN_EMAIL)
    page.locator("#login input[name=password]").fill(ADMIN_PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#sequences-view")).to_be_visible()
    page.goto(f"{server.base}/admin/#/sequences/{server.sequence_id}")
    expect(page.locator("#sequence-view")).to_be_visible()
    for view in ("workers", "jobs", "costs", "queue"):
        page.locator(f"#nav-{view}").click()
        page.wait_for_load_state("networkidle")
    # An element styled by the pages' helper keeps its style under the policy.
    width = page.evaluate("""async () => {
        const { el } = await import('/common/dom.js');
        const node = el('span', { style: 'width: 17px; display: inline-block' });
        document.body.append(node);
        return node.getBoundingClientRect().width; }""")
    assert width == 17
    assert problems == [], problems


def test_the_worker_portal_works_under_its_policy(
    watched_page: tuple[Page, list[str]], live_server: LiveServer,
) -> None:
    page, problems = watched_page
    server = live_server
    server.admin("POST", "/api/portal/workers", {"email": EMAIL, "password": PASSWORD})
    page.goto(f"{server.base}/market/")
    page.locator("#login input[name=email]").fill(EMAIL)
    page.locator("#login input[name=password]").fill(PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#hits-view")).to_be_visible()
    page.wait_for_load_state("networkidle")
    assert problems == [], problems
