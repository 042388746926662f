"""An invite link carries its token in the fragment: the browser never sends it (nor does a
log see it), the page takes it out of the address at once, and the worker registers with it;
a link made before, with the token in the query, still works."""

from __future__ import annotations

from urllib.parse import urlsplit

from playwright.sync_api import Page, expect

from tests.browser.conftest import LiveServer


def _invite(server: LiveServer) -> dict:
    invite = server.admin("POST", "/api/portal/invites", {})
    assert isinstance(invite, dict)
    return invite


def _register(page: Page, email: str) -> None:
    form = page.locator("#register")
    expect(form).to_be_visible()
    form.locator("input[name=email]").fill(email)
    form.locator("input[name=password]").fill("invited worker password")
    form.locator("button[type=submit]").click()
    expect(page.locator("#notice")).to_contain_text("Account created")
    expect(form).to_be_hidden()


def test_an_invite_in_the_fragment_registers_and_never_reaches_the_server(
    page: Page, live_server: LiveServer,
) -> None:
    invite = _invite(live_server)
    url = urlsplit(invite["url"])
    assert url.fragment == f"invite={invite['invite']}" and not url.query
    requested: list[str] = []
    page.on("request", lambda request: requested.append(request.url))
    page.goto(f"{live_server.base}/market/#invite={invite['invite']}")
    _register(page, "fragment-invite@example.org")
    assert invite["invite"] not in page.url
    assert not [u for u in requested if invite["invite"] in u], requested


def test_an_older_link_with_the_invite_in_the_query_still_registers(
    page: Page, live_server: LiveServer,
) -> None:
    invite = _invite(live_server)
    page.goto(f"{live_server.base}/market/?invite={invite['invite']}")
    _register(page, "query-invite@example.org")
    assert invite["invite"] not in page.url
