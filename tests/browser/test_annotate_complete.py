"""The page completes the way its crowd expects, after the server accepted the submission:
Prolific's redirect takes the worker to the crowd's completion page (a stand-in served on
loopback), the whole window when the page is framed; the portal's kind sends the framed page's
worker back to the portal's list. In the portal, one annotation app runs at a time: the
preview's is unloaded after Accept.

The completion is the one the start reply gave, as the page keeps it in its address's fragment
beside the token (tests/backend/crowd/test_completion.py covers the reply)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, urlencode, urlsplit

import httpx
import pytest
from playwright.sync_api import Frame, Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import READY, confirm_submit, open_task
from tests.browser.test_portal import _publish, _sign_in, portal_page

__all__ = ["portal_page"]

LAST = CLIP_FRAMES - 1
VIEW = 1
CODE = "C1A2B3C4"
PORTAL_EMAIL, PORTAL_PASSWORD = "portal-complete@example.org", "portal complete password"
SHOTS = Path("/tmp/shots-page")
SIZES = ((1440, 900), (1024, 700))


class _CompletionPage(BaseHTTPRequestHandler):
    """A crowd's completion page: says which code it was given."""

    def do_GET(self) -> None:
        code = parse_qs(urlsplit(self.path).query).get("cc", [""])[0]
        body = f"<title>Study complete</title><h1>Completed with code {code}</h1>".encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *_args: object) -> None:
        pass


@pytest.fixture
def crowd_site() -> Iterator[str]:
    """A completion page on loopback (another origin than the app's); its base URL."""
    site = ThreadingHTTPServer(("127.0.0.1", 0), _CompletionPage)
    thread = threading.Thread(target=site.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{site.server_address[1]}"
    site.shutdown()
    site.server_close()


def _save_whole_hand(server: LiveServer, task: dict, token: str) -> None:
    """Every joint placed on its true position in the first and last frame (so the page's
    checks pass), saved through the page's API."""
    first, last = server.truth(task["serial"], 0), server.truth(task["serial"], LAST)
    tracks = [{"point": p, "keyframes": [[0, *map(float, first[p]), 1],
                                         [LAST, *map(float, last[p]), 1]]} for p in range(21)]
    resp = httpx.put(f"{server.base}/api/annotate/tracks", timeout=30,
                     json={"version": 0, "tracks": tracks, "working_time_s": 60.0},
                     headers={"Authorization": f"Bearer {token}"})
    assert resp.status_code == 200, resp.text


def _submit(target: Page | Frame) -> None:
    target.locator("#submit").click()
    confirm_submit(target.locator("#submit-dialog")).click()


def test_redirect_completion_takes_the_worker_to_the_crowds_completion_page(
    live_server: LiveServer, page: Page, crowd_site: str
) -> None:
    server = live_server
    task = server.task("hand", VIEW)
    link = server.assign(task, "W-redirect")
    _save_whole_hand(server, task, link["token"])
    done = f"{crowd_site}/submissions/complete?cc={CODE}"
    fragment = urlencode({"token": link["token"], "completion": "redirect",
                          "completion_url": done})
    open_task(page, f"{server.base}/annotate/?assignmentId={link['external_id']}#{fragment}")
    assert page.evaluate("window.__dexlabel.page.params.completion") == {
        "kind": "redirect", "url": done}
    _submit(page)
    page.wait_for_url(done)
    expect(page.locator("h1")).to_have_text(f"Completed with code {CODE}")
    assert server.worker_get_task(link["token"])["mode"] == "submitted"


def test_a_portal_completion_of_a_page_standing_alone_opens_the_portals_list(
    live_server: LiveServer, page: Page
) -> None:
    server = live_server
    task = server.task("hand", VIEW)
    link = server.assign(task, "W-portal-alone")
    _save_whole_hand(server, task, link["token"])
    fragment = urlencode({"token": link["token"], "completion": "portal",
                          "completion_url": "/market/#/hits"})
    open_task(page, f"{server.base}/annotate/?assignmentId={link['external_id']}#{fragment}")
    _submit(page)
    page.wait_for_url(f"{server.base}/market/#/hits")
    expect(page.locator("#login-view")).to_be_visible()  # the portal, asking to sign in
    assert server.worker_get_task(link["token"])["mode"] == "submitted"


def test_a_redirect_to_a_script_url_is_not_followed(live_server: LiveServer, page: Page) -> None:
    """A forged fragment cannot turn the completion into a script: the page completes as
    before (no turkSubmitTo: it stays, submitted)."""
    server = live_server
    task = server.task("hand", VIEW)
    link = server.assign(task, "W-forged")
    _save_whole_hand(server, task, link["token"])
    fragment = urlencode({"token": link["token"], "completion": "redirect",
                          "completion_url": "javascript:window.__forged=1"})
    open_task(page, f"{server.base}/annotate/?assignmentId={link['external_id']}#{fragment}")
    assert page.evaluate("window.__dexlabel.page.params.completion") is None
    _submit(page)
    expect(page.locator("#banner")).to_have_text("Submitted. Thank you!")
    assert page.evaluate("window.__forged") is None
    assert page.url.startswith(f"{server.base}/annotate/")


def _shots(page: Page, name: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    for width, height in SIZES:
        page.set_viewport_size({"width": width, "height": height})
        page.wait_for_timeout(200)
        page.screenshot(path=str(SHOTS / f"{name}-{width}x{height}.png"))


def _accept_in_portal(page: Page, server: LiveServer, email: str) -> tuple[Frame, dict]:
    """A new portal worker previews a new hand HIT and accepts it: (the work frame, the task).
    The preview's app is gone once the work's runs."""
    server.admin("POST", "/api/portal/workers", {"email": email, "password": PORTAL_PASSWORD})
    task = server.task("hand", VIEW)
    _mturk, hit_id = _publish(server, task)
    _sign_in(page, server, email, PORTAL_PASSWORD)
    page.locator(f'tr[data-hit="{hit_id}"] a.hit-title').click()
    preview = page.wait_for_selector("#preview-frame iframe").content_frame()
    assert preview is not None
    preview.wait_for_function(READY)
    assert len(page.frames) == 2  # the portal and the preview

    page.locator("#accept").click()
    work = page.wait_for_selector("#work-frame iframe").content_frame()
    assert work is not None
    work.wait_for_function(READY)
    assert page.locator("iframe").count() == 1
    assert page.locator("#preview-frame").evaluate("box => box.childElementCount") == 0
    assert len(page.frames) == 2  # the portal and the work: the preview's app is gone
    return work, task


def _reopen_completing(work: Frame, server: LiveServer, task: dict, kind: str,
                       url: str) -> str:
    """The whole hand saved, the work page opened again with the completion ``kind`` a HIT
    of another crowd starts it with; the assignment token."""
    token = parse_qs(urlsplit(work.url).fragment)["token"][0]
    _save_whole_hand(server, task, token)
    query = urlsplit(work.url).query
    fragment = urlencode({"token": token, "completion": kind, "completion_url": url})
    work.goto("about:blank")  # a new load (the address differs in its fragment only)
    work.goto(f"{server.base}/annotate/?{query}#{fragment}")
    work.wait_for_function(READY)
    assert work.evaluate("window.__dexlabel.page.params.completion")["kind"] == kind
    return token


def test_in_the_portal_one_app_runs_and_a_portal_completion_returns_to_the_list(
    live_server: LiveServer, portal_page: Page
) -> None:
    page, server = portal_page, live_server
    work, task = _accept_in_portal(page, server, PORTAL_EMAIL)
    _shots(page, "portal-accepted")

    token = _reopen_completing(work, server, task, "portal", "/market/#/hits")
    _submit(work)
    expect(page.locator("#notice")).to_contain_text("Submitted")
    expect(page.locator("#hits-view")).to_be_visible()
    assert page.locator("iframe").count() == 0
    assert server.worker_get_task(token)["mode"] == "submitted"
    _shots(page, "portal-submitted")


def test_a_framed_redirect_completion_takes_the_whole_window(
    live_server: LiveServer, portal_page: Page, crowd_site: str
) -> None:
    page, server = portal_page, live_server
    work, task = _accept_in_portal(page, server, "portal-redirect@example.org")
    done = f"{crowd_site}/submissions/complete?cc={CODE}"
    token = _reopen_completing(work, server, task, "redirect", done)
    _submit(work)
    page.wait_for_url(done)
    expect(page.locator("h1")).to_have_text(f"Completed with code {CODE}")
    assert server.worker_get_task(token)["mode"] == "submitted"
