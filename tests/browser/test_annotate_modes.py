"""The page outside plain editing: preview before the HIT is accepted, a forged link, a second
tab that saved first (409), the MTurk-style task link, and what submit refuses."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qs, urlparse

import httpx
from playwright.sync_api import BrowserContext, Page, expect

from backend.config import DEV_MARKET_REQUESTERS
from tests.backend.market.helpers import external_question, make_client
from tests.browser.conftest import LiveServer
from tests.browser.helpers import (
    click_image,
    confirm_submit,
    drag_image,
    frames_shown,
    goto_frame,
    open_task,
    point_states,
    server_keyframes,
    value_at,
    wait_saved,
)


def _where(page: Page) -> list[int]:
    """[current frame, active point]."""
    return page.evaluate("[window.__dexlabel.editor.frame, window.__dexlabel.editor.active]")


def _click_timeline(page: Page, point: int, frame: int) -> None:
    """Clicks the timeline 3 px right of the centre of ``frame`` in ``point``'s row."""
    box = page.locator(".timeline-canvas").bounding_box()
    centre = page.evaluate("([p, f]) => window.__dexlabel.page.timeline.cellCentre(p, f)",
                           [point, frame])
    page.mouse.click(box["x"] + centre["x"] + 3, box["y"] + centre["y"])


# The page writes frame ranges with an en dash.
EN_DASH = "\u2013"
CONFLICT = "This assignment was changed in another tab — reload to continue"


def test_preview_shows_frames_and_instructions_but_cannot_edit_or_submit(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    link = live_server.admin("POST", f"/api/tasks/{live_server.task('hand')['id']}/preview-token")
    open_task(page, link["page_url"])
    expect(page.locator("#banner")).to_contain_text("accept the HIT")
    expect(page.locator("#instructions svg.hand-diagram")).to_be_visible()
    expect(page.locator("#submit")).to_be_disabled()
    assert frames_shown(page)
    click_image(page, 320, 240)
    page.keyboard.press("o")
    page.keyboard.press("ArrowRight")
    assert page.evaluate("window.__dexlabel.editor.frame") == 1, "frames can still be stepped"
    assert point_states(page) == ["unplaced"] * 21
    assert page.evaluate("window.__dexlabel.saver") is None
    page.screenshot(path=str(output_dir / "preview.png"))


def test_a_forged_token_is_refused_and_the_page_says_so(
    live_server: LiveServer, page: Page
) -> None:
    real = live_server.assign(live_server.task("hand"), "W-forge")["token"]
    body, _, signature = real.partition(".")
    forged = f"{body}.{signature[::-1]}"
    open_task(page, live_server.page_url(forged, assignmentId="A1"))
    expect(page.locator("#banner")).to_contain_text("This link cannot open the task")
    expect(page.locator("#banner")).to_contain_text("signature")
    expect(page.locator("#submit")).to_be_disabled()
    assert page.evaluate("window.__dexlabel.ready") is False


def test_a_stale_tab_gets_409_and_stops_saving(
    live_server: LiveServer, context: BrowserContext, page: Page, output_dir: Path
) -> None:
    link = live_server.assign(live_server.task("hand"), "W-tabs")
    url = live_server.page_url(link["token"], assignmentId=link["external_id"])
    open_task(page, url)
    other = context.new_page()
    open_task(other, url)

    click_image(page, 300, 200)
    wait_saved(page)
    click_image(other, 100, 100)
    expect(other.locator("#banner")).to_have_text(CONFLICT)
    expect(other.locator("#save-status")).to_have_text(CONFLICT)
    expect(other.locator("#submit")).to_be_disabled()
    click_image(other, 150, 150)
    assert point_states(other)[1] == "unplaced", "the stale tab no longer edits"
    other.screenshot(path=str(output_dir / "stale-tab.png"))
    stored = server_keyframes(live_server.worker_get_task(link["token"])["assignment"])
    assert len(stored[0]) == 1 and abs(stored[0][0][1] - 300) <= 1, "the first tab's work stands"
    other.close()


def _accepted_hit(live_server: LiveServer, task: dict) -> dict:
    """The task published as a HIT on the built-in marketplace and accepted by a portal
    worker: the portal's reply (assignment_id, hit_id, work_url as MTurk frames it)."""
    token = live_server.admin("POST", f"/api/tasks/{task['id']}/preview-token")["token"]
    key, secret = DEV_MARKET_REQUESTERS.split(":")
    hit = make_client(live_server.base, (key, secret)).create_hit(
        Title="Track 21 hand joints (task link)", Description="Click each joint",
        Reward="0.50", MaxAssignments=1, LifetimeInSeconds=3600,
        AssignmentDurationInSeconds=1800, AutoApprovalDelayInSeconds=86400,
        Question=external_question(f"{live_server.base}/annotate/?task={token}", 700))["HIT"]
    email, password = "task-link-worker@example.org", "task link worker password"
    live_server.admin("POST", "/api/portal/workers", {"email": email, "password": password})
    login = httpx.post(f"{live_server.base}/api/portal/login", timeout=30,
                       json={"email": email, "password": password}).json()
    accepted = httpx.post(f"{live_server.base}/api/portal/hits/{hit['HITId']}/accept",
                          headers={"Authorization": f"Bearer {login['access_token']}"},
                          timeout=30)
    assert accepted.status_code == 200, accepted.text
    return accepted.json()


def test_mturk_task_link_starts_the_assignment_and_puts_its_token_in_the_address(
    live_server: LiveServer, page: Page
) -> None:
    accepted = _accepted_hit(live_server, live_server.task("hand", 1))
    open_task(page, accepted["work_url"])
    address = urlparse(page.url)
    query = parse_qs(address.query)
    assert "task" not in query and query["assignmentId"] == [accepted["assignment_id"]]
    # The assignment token rides in the fragment, which no request (nor access log) carries.
    assert "token" not in query
    read = live_server.worker_get_task(parse_qs(address.fragment)["token"][0])
    assert read["mode"] == "edit"
    assert read["assignment"]["external_id"] == accepted["assignment_id"]
    click_image(page, 200, 200)
    wait_saved(page)
    page.reload()
    page.wait_for_function("window.__dexlabel.ready")
    assert point_states(page)[0] == "keyframe", "the reload reopened the same assignment"


def test_incomplete_work_is_listed_frame_by_frame_and_cannot_be_submitted(
    live_server: LiveServer, page: Page
) -> None:
    link = live_server.assign(live_server.task("hand"), "W-incomplete")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    click_image(page, 100, 300)
    click_image(page, 110, 300)
    goto_frame(page, 6)
    page.keyboard.press("o")  # point 2 occluded from frame 6 on: frames 0-5 still missing
    page.locator("#submit").click()
    dialog = page.locator("#submit-dialog")
    problems = dialog.locator(".submit-problems li")
    expect(problems).to_have_count(2)
    expect(problems.nth(0)).to_contain_text(f"Frames 0{EN_DASH}5: Thumb PIP, Thumb DIP, Thumb tip")
    expect(problems.nth(1)).to_contain_text(f"Frames 6{EN_DASH}11: Thumb DIP, Thumb tip")
    expect(dialog.locator(".submit-confirm")).to_be_disabled()
    problems.nth(1).locator("button").click()
    expect(dialog).not_to_be_visible()
    assert _where(page) == [6, 3]


def test_work_without_movement_needs_a_confirm_then_submits_without_a_marketplace(
    live_server: LiveServer, page: Page
) -> None:
    link = live_server.assign(live_server.task("hand"), "W-static")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    for i in range(21):
        click_image(page, 100 + 12 * i, 300)
    page.locator("#submit").click()
    dialog = page.locator("#submit-dialog")
    expect(dialog.locator(".submit-summary")).to_contain_text("Every point is placed")
    expect(dialog.locator(".submit-warnings")).to_contain_text("no point moves")
    expect(dialog.locator(".submit-confirm")).to_be_disabled()
    confirm_submit(dialog).click()
    expect(page.locator("#banner")).to_have_text("Submitted. Thank you!")
    assert urlparse(page.url).path == "/annotate/", "no marketplace to post to"
    assert live_server.worker_get_task(link["token"])["mode"] == "submitted"
    page.reload()
    page.wait_for_function("window.__dexlabel.ready")
    expect(page.locator("#banner")).to_contain_text("has been submitted")
    click_image(page, 400, 400)
    assert page.evaluate("window.__dexlabel.store.editCount") == 0


def test_drag_moves_only_the_point_under_the_cursor_and_undo_redo_restore_it(
    live_server: LiveServer, page: Page
) -> None:
    link = live_server.assign(live_server.task("hand"), "W-drag")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    click_image(page, 200, 200)
    click_image(page, 205, 200)  # a neighbour 5 px away: placing never selects it instead
    assert point_states(page)[:3] == ["keyframe", "keyframe", "unplaced"]
    goto_frame(page, 10)
    drag_image(page, (205, 200), (260, 230))
    assert value_at(page, 0, 10)["x"] == 200, "the neighbour did not move"
    moved = value_at(page, 1, 10)
    assert abs(moved["x"] - 260) <= 1 and moved["state"] == "keyframe"
    page.keyboard.press("Control+z")
    assert value_at(page, 1, 10)["state"] == "interpolated"
    page.keyboard.press("Control+Shift+z")
    assert value_at(page, 1, 10) == moved
    page.keyboard.press("[")
    assert page.evaluate("window.__dexlabel.editor.frame") == 0
    page.keyboard.press("]")
    assert page.evaluate("window.__dexlabel.editor.frame") == 10
    goto_frame(page, 3)
    page.locator('.point-row[data-point="0"]').click()
    _click_timeline(page, point=1, frame=10)  # a keyframe of point 1: jump there, select it
    assert _where(page) == [10, 1]
    page.keyboard.press("Delete")
    assert value_at(page, 1, 10)["state"] == "interpolated"
    page.locator("#fps").select_option("30")
    goto_frame(page, 0)
    page.keyboard.press("Space")
    page.wait_for_function("window.__dexlabel.editor.frame >= 4")
    page.keyboard.press("Space")
    paused_at = page.evaluate("window.__dexlabel.editor.frame")
    page.wait_for_timeout(150)
    assert page.evaluate("window.__dexlabel.editor.frame") == paused_at
    page.keyboard.press("Shift+?")
    expect(page.locator("#shortcuts")).to_be_visible()
    expect(page.locator("#shortcuts")).to_contain_text("previous / next keyframe")
    page.keyboard.press("Escape")
    expect(page.locator("#shortcuts")).not_to_be_visible()
    wait_saved(page)
    stored = server_keyframes(live_server.worker_get_task(link["token"])["assignment"])
    assert [len(stored[0]), len(stored[1])] == [1, 1]
