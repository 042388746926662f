"""A worker new to the portal, at 1440x900: the sign-in page says how to get an account; a HIT's
link opened in a new tab lands on that HIT after signing in; after Accept the keys step the
framed page's frames without a click; all 21 joints' list rows and timeline rows are in view."""

from __future__ import annotations

from pathlib import Path

from playwright.sync_api import Frame, Page, expect

from backend.config import DEV_MARKET_ACCESS_KEY, DEV_MARKET_REQUESTERS
from tests.backend.market.helpers import external_question, make_client
from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import READY

EMAIL, PASSWORD = "newcomer@example.org", "newcomer portal password"
DEV_SECRET = DEV_MARKET_REQUESTERS.split(":")[1]
TITLE = "Track 21 hand joints (newcomer)"
LAST = CLIP_FRAMES - 1


def _publish(server: LiveServer, task: dict) -> str:
    """The task as a HIT of the built-in marketplace, published with boto3; its HITId."""
    token = server.admin("POST", f"/api/tasks/{task['id']}/preview-token")["token"]
    mturk = make_client(server.base, (DEV_MARKET_ACCESS_KEY, DEV_SECRET))
    return mturk.create_hit(
        Title=TITLE, Description="Click each joint", Reward="0.40", MaxAssignments=1,
        LifetimeInSeconds=3600, AssignmentDurationInSeconds=1800,
        AutoApprovalDelayInSeconds=86400,
        Question=external_question(f"{server.base}/annotate/?task={token}", 700))["HIT"]["HITId"]


def _work_frame(page: Page) -> Frame:
    frame = page.wait_for_selector("#work-frame iframe").content_frame()
    assert frame is not None
    frame.wait_for_function(READY)
    assert frame.evaluate("window.__dexlabel.error") in (None, False, "")
    return frame


def _rows_in_view(frame: Frame) -> dict:
    """Which point-list rows lie inside the list's visible box and the frame's window, and
    whether the timeline shows all its rows without scrolling."""
    return frame.evaluate("""() => {
      const list = document.querySelector('#point-list').getBoundingClientRect();
      const rows = [...document.querySelectorAll('.point-row')].map((r) => {
        const b = r.getBoundingClientRect();
        return b.top >= list.top - 1 && b.bottom <= list.bottom + 1 && b.bottom <= innerHeight
          && b.height > 0;
      });
      const tl = document.querySelector('#timeline');
      const box = tl.getBoundingClientRect();
      return { rows, timelineFits: tl.scrollHeight <= tl.clientHeight + 1,
               timelineInWindow: box.top >= 0 && box.bottom <= innerHeight + 1,
               timelineRows: window.__dexlabel.page.timeline.colors.length };
    }""")


def test_a_hit_link_opened_signed_out_lands_on_that_hit_and_keys_work_after_accept(
    live_server: LiveServer, browser, output_dir: Path
) -> None:
    server = live_server
    server.admin("POST", "/api/portal/workers", {"email": EMAIL, "password": PASSWORD})
    hit_id = _publish(server, server.task("hand", 1))
    ctx = browser.new_context(viewport={"width": 1440, "height": 900})
    ctx.set_default_timeout(15000)
    page = ctx.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    try:
        # A new tab: no session yet. The sign-in form says how accounts are had.
        page.goto(f"{server.base}/market/#/hits/{hit_id}")
        expect(page.locator("#login")).to_be_visible()
        how = page.locator("#how-to-join")
        expect(how).to_be_visible()
        expect(how).to_contain_text("invite link")
        expect(how).to_contain_text("creates your account")
        expect(page.locator("#login-next")).to_have_text(
            "Sign in to open the HIT your link is for.")
        for width, height in [(1440, 900), (1024, 700)]:
            page.set_viewport_size({"width": width, "height": height})
            page.screenshot(path=str(output_dir / f"newcomer-login-{width}x{height}.png"))
        page.set_viewport_size({"width": 1440, "height": 900})
        page.locator("#login input[name=email]").fill(EMAIL)
        page.locator("#login input[name=password]").fill(PASSWORD)
        page.locator("#login button[type=submit]").click()
        expect(page.locator("#preview-view")).to_be_visible()
        expect(page.locator("#preview-title")).to_have_text(TITLE)
        assert page.evaluate("location.hash") == f"#/hits/{hit_id}"

        page.locator("#accept").click()
        frame = _work_frame(page)
        # The keys go to the framed page's image at once: no click in it first.
        assert page.evaluate("document.activeElement.tagName") == "IFRAME"
        expect(frame.locator("#view")).to_be_focused()
        page.keyboard.press("ArrowRight")
        assert frame.evaluate("window.__dexlabel.editor.frame") == 1
        page.keyboard.press("End")
        assert frame.evaluate("window.__dexlabel.editor.frame") == LAST
        page.keyboard.press("Home")
        assert frame.evaluate("window.__dexlabel.editor.frame") == 0

        # All 21 joints: every row of the point list and of the timeline in view at 1440x900.
        seen = _rows_in_view(frame)
        assert seen["rows"] == [True] * 21, seen
        assert seen["timelineRows"] == 21 and seen["timelineFits"], seen
        assert seen["timelineInWindow"], seen
        page.screenshot(path=str(output_dir / "newcomer-portal-work-1440x900.png"))
        page.set_viewport_size({"width": 1024, "height": 700})
        page.wait_for_timeout(300)
        page.screenshot(path=str(output_dir / "newcomer-portal-work-1024x700.png"))
        # Smaller, the lists scroll: the last joint is still reachable.
        frame.locator('.point-row[data-point="20"]').scroll_into_view_if_needed()
        expect(frame.locator('.point-row[data-point="20"]')).to_be_in_viewport()
    finally:
        ctx.close()
    assert not errors, f"uncaught errors in the page: {errors}"
