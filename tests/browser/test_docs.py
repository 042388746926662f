"""The interactive API documentation in a real browser with no way out: every request that
leaves the app is blocked, and /docs (Swagger UI) still renders every operation."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest
from playwright.sync_api import Page, Route, expect

from tests.browser.conftest import LiveServer

HTTP_METHODS = {"get", "put", "post", "delete", "patch", "head", "options", "trace"}


@pytest.fixture
def offline_page(page: Page, live_server: LiveServer) -> Iterator[tuple[Page, list[str]]]:
    """The test page with every request to another host than the app's aborted (and listed),
    and every answer of the app that is not a success listed."""
    app_host = urlsplit(live_server.base).netloc
    blocked: list[str] = []
    failed: list[str] = []

    def only_the_app(route: Route) -> None:
        url = route.request.url
        if url.startswith(("data:", "blob:")) or urlsplit(url).netloc == app_host:
            route.continue_()
        else:
            blocked.append(url)
            route.abort()

    page.route("**/*", only_the_app)
    page.on("response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400
            else None)
    page.on("requestfailed", lambda r: None if r.url in blocked else failed.append(r.url))
    yield page, blocked
    assert not failed, f"requests to the app that failed: {failed}"


def _operations(server: LiveServer) -> list[tuple[str, str]]:
    spec = httpx.get(f"{server.base}/openapi.json", timeout=30).json()
    return [(method, path) for path, item in spec["paths"].items()
            for method in item if method in HTTP_METHODS]


def test_swagger_ui_renders_every_operation_without_the_network(
    offline_page: tuple[Page, list[str]], live_server: LiveServer, output_dir: Path
) -> None:
    page, blocked = offline_page
    operations = _operations(live_server)
    assert len(operations) > 20
    page.goto(f"{live_server.base}/docs")
    expect(page.locator(".swagger-ui .info .title")).to_contain_text("dexlabel")
    blocks = page.locator(".swagger-ui .opblock")
    expect(blocks).to_have_count(len(operations))
    jobs = page.locator(".swagger-ui .opblock-summary-path[data-path='/api/jobs']")
    expect(jobs).not_to_have_count(0)
    # The page's styles came from the app: an operation's method badge is laid out by them.
    get_badge = page.locator(".swagger-ui .opblock-get .opblock-summary-method").first
    assert get_badge.evaluate("b => getComputedStyle(b).backgroundColor") != "rgba(0, 0, 0, 0)"
    page.screenshot(path=str(output_dir / "docs-swagger.png"))
    assert not blocked, f"the page reached outside the app: {blocked}"



def test_authorize_on_the_docs_page_sends_the_admin_token(
    offline_page: tuple[Page, list[str]], live_server: LiveServer, output_dir: Path
) -> None:
    """A newcomer pastes a token from POST /api/auth/token into Authorize and tries an admin
    operation from the page: it answers 200 with their account."""
    page, blocked = offline_page
    page.goto(f"{live_server.base}/docs")
    page.locator(".swagger-ui .auth-wrapper button.authorize").click()
    modal = page.locator(".swagger-ui .modal-ux")
    expect(modal).to_contain_text("bearer")
    modal.locator("input").first.fill(live_server.admin_token)
    modal.locator("button.authorize").click()
    modal.locator("button.btn-done").click()
    operation = page.locator(".swagger-ui .opblock-get").filter(
        has=page.locator(".opblock-summary-path[data-path='/api/auth/me']"))
    operation.locator(".opblock-summary").click()
    operation.locator("button.try-out__btn").click()
    operation.locator("button.execute").click()
    status = operation.locator(".live-responses-table tbody .response-col_status").first
    expect(status).to_have_text("200")
    expect(operation.locator(".live-responses-table")).to_contain_text("email")
    page.screenshot(path=str(output_dir / "docs-authorized.png"))
    assert not blocked, f"the page reached outside the app: {blocked}"
