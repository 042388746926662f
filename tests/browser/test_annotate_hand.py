"""A worker annotates a hand task in the real page: 21 joints on two keyframes, an occluded
span, a reload with unsaved work, a network outage, and submit through the marketplace form."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qs

from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import (
    assert_rows_close,
    click_image,
    confirm_submit,
    drag_image,
    frames_shown,
    goto_frame,
    open_task,
    place_joints,
    point_states,
    select_point,
    server_keyframes,
    value_at,
    wait_saved,
    zoom_on_points,
)

LAST = CLIP_FRAMES - 1
# View 1 of the synthetic capture shows the whole hand in the first and the last frame.
VIEW = 1
OCCLUDED_POINT = 4  # thumb tip
OCCLUDED_FROM, VISIBLE_AGAIN = 4, 8


def _zoom_on_hand(page: Page, server: LiveServer, serial: str) -> None:
    zoom_on_points(page, [*server.truth(serial, 0), *server.truth(serial, LAST)])


def _first_keyframe_with_a_reload(page: Page, server: LiveServer, link: dict, first) -> None:
    """Half the joints while saves fail, a reload (the work comes back from localStorage), the
    saves go through once the server is reachable, then the other half."""
    serial = server.worker_get_task(link["token"])["task"]["serial"]
    page.route("**/api/annotate/tracks", lambda route: route.abort())
    _zoom_on_hand(page, server, serial)
    place_joints(page, first, range(10))
    expect(page.locator("#save-status")).to_contain_text("not saved yet")
    page.reload()
    page.wait_for_function("window.__dexlabel.ready")
    expect(page.locator("#banner")).to_contain_text("Restored your unsaved work")
    assert point_states(page) == ["keyframe"] * 10 + ["unplaced"] * 11
    page.unroute("**/api/annotate/tracks")
    page.evaluate("window.dispatchEvent(new Event('online'))")
    wait_saved(page)
    stored = server_keyframes(server.worker_get_task(link["token"])["assignment"])
    assert [len(stored[p]) for p in range(21)] == [1] * 10 + [0] * 11
    _zoom_on_hand(page, server, serial)
    place_joints(page, first, range(10, 21))
    assert point_states(page) == ["keyframe"] * 21


def _second_keyframe(page: Page, first, last) -> None:
    """Drags every joint from where it was held to where it is in the last frame."""
    goto_frame(page, LAST)
    assert point_states(page) == ["interpolated"] * 21
    for p in range(21):
        drag_image(page, tuple(first[p]), tuple(last[p]))
    assert point_states(page) == ["keyframe"] * 21
    for p in (0, 8, 20):
        v = value_at(page, p, LAST)
        assert abs(v["x"] - last[p][0]) < 1 and abs(v["y"] - last[p][1]) < 1, (p, v, last[p])


def _occlude_thumb_tip(page: Page) -> None:
    """The thumb tip is hidden behind the object from frame 4 until frame 8."""
    select_point(page, OCCLUDED_POINT)
    goto_frame(page, OCCLUDED_FROM)
    page.keyboard.press("o")
    goto_frame(page, VISIBLE_AGAIN)
    page.keyboard.press("o")
    goto_frame(page, 6)
    assert point_states(page)[OCCLUDED_POINT] == "occluded"
    assert point_states(page)[OCCLUDED_POINT + 1] == "interpolated"
    page.keyboard.press("[")
    assert page.evaluate("window.__dexlabel.editor.frame") == OCCLUDED_FROM


def _submit_through_marketplace(page: Page, turk: str) -> dict[str, list[str]]:
    """Submits; returns the form the page posted to {turkSubmitTo}/mturk/externalSubmit."""
    posted: list[str] = []

    def marketplace(route) -> None:
        posted.append(route.request.post_data or "")
        route.fulfill(status=200, content_type="text/html", body="<p>HIT complete</p>")

    page.route(f"{turk}/mturk/externalSubmit", marketplace)
    page.locator("#submit").click()
    dialog = page.locator("#submit-dialog")
    expect(dialog).to_contain_text("Every point is placed or marked occluded")
    confirm = confirm_submit(dialog)
    with page.expect_navigation():
        confirm.click()
    assert len(posted) == 1
    return parse_qs(posted[0])


def test_hand_task_two_keyframes_occlusion_reload_and_marketplace_submit(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    task = live_server.task("hand", VIEW)
    link = live_server.assign(task, "W-hand")
    turk = f"{live_server.base}/mturk-sandbox"
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"],
                                         hitId="HIT1", workerId="W-hand", turkSubmitTo=turk))
    assert page.evaluate("window.__dexlabel.timings.allFrames") is not None
    assert frames_shown(page)
    first, last = live_server.truth(task["serial"], 0), live_server.truth(task["serial"], LAST)

    _first_keyframe_with_a_reload(page, live_server, link, first)
    _second_keyframe(page, first, last)
    _occlude_thumb_tip(page)
    wait_saved(page)
    dense = live_server.admin("GET", f"/api/assignments/{link['assignment_id']}/dense")
    thumb_tip = next(p for p in dense["points"] if p["point"] == OCCLUDED_POINT)
    hidden = [f for f, v in enumerate(thumb_tip["visible"]) if not v]
    assert hidden == list(range(OCCLUDED_FROM, VISIBLE_AGAIN))
    assert all(s != "unplaced" for p in dense["points"] for s in p["state"])
    goto_frame(page, 5)
    page.screenshot(path=str(output_dir / "hand-occluded-span.png"))
    goto_frame(page, LAST)
    assert frames_shown(page)
    page.screenshot(path=str(output_dir / "hand-annotated.png"))

    form = _submit_through_marketplace(page, turk)
    read = live_server.worker_get_task(link["token"])
    assert read["mode"] == "submitted" and read["assignment"]["status"] == "submitted"
    assert form["assignmentId"] == [link["external_id"]]
    assert form["result"] == [f"submitted:{read['assignment']['version']}"]
    assert read["assignment"]["edit_count"] >= 42 and read["assignment"]["working_time_s"] > 0


def test_edits_made_offline_are_kept_and_flushed_when_the_network_returns(
    live_server: LiveServer, page: Page
) -> None:
    task = live_server.task("hand", 0)
    link = live_server.assign(task, "W-offline")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    click_image(page, 300, 200)
    click_image(page, 320, 210)
    wait_saved(page)

    page.context.set_offline(True)
    goto_frame(page, 5)
    click_image(page, 100, 100)  # the active point (2) placed for the first time, at frame 5
    select_point(page, 0)
    drag_image(page, (300, 200), (340, 260))
    page.keyboard.press("o")
    status = page.locator("#save-status")
    expect(status).to_contain_text("changes not saved yet")
    expect(status).to_have_attribute("data-state", "offline", timeout=10000)
    stored = server_keyframes(live_server.worker_get_task(link["token"])["assignment"])
    assert_rows_close(stored[0], [[0, 300, 200, 1]])
    assert stored[2] == []

    page.context.set_offline(False)
    wait_saved(page)
    stored = server_keyframes(live_server.worker_get_task(link["token"])["assignment"])
    assert_rows_close(stored[0], [[0, 300, 200, 1], [5, 340, 260, 0]])
    assert_rows_close(stored[2], [[5, 100, 100, 1]])
