"""An object task in the real page: step 1 picks 2 landmarks on the highlighted object, step 2
tracks them through the clip, then submit."""

from __future__ import annotations

from pathlib import Path

from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import (
    click_image,
    confirm_submit,
    drag_image,
    goto_frame,
    object_pixels,
    open_task,
    point_states,
    server_keyframes,
    wait_saved,
)

LAST = CLIP_FRAMES - 1
VIEW = 1


def _inside(polygon: list[list[float]], x: float, y: float) -> bool:
    inside = False
    for (x0, y0), (x1, y1) in zip(polygon, polygon[1:] + polygon[:1], strict=True):
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def test_object_task_picks_two_landmarks_tracks_them_and_submits(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    task = live_server.task("object", VIEW)
    polygon = task["highlight"]["polygon"]
    link = live_server.assign(task, "W-object")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    step = page.locator("#step-banner")
    expect(step).to_contain_text("Step 1 of 2: pick 2 distinctive points")
    expect(page.locator("#submit")).to_be_disabled()
    start = page.locator("#start-tracking")
    expect(start).to_be_disabled()

    first = object_pixels(live_server, task["serial"], 0)
    last = object_pixels(live_server, task["serial"], LAST)
    shift = last.mean(axis=0) - first.mean(axis=0)
    centre = first.mean(axis=0)
    top = (centre[0], first[:, 1].min() + 6)
    bottom = (centre[0], first[:, 1].max() - 6)
    assert _inside(polygon, *top) and _inside(polygon, *bottom), "landmarks on the highlight"
    click_image(page, *top)
    expect(start).to_be_disabled()
    click_image(page, *bottom)
    assert point_states(page) == ["keyframe", "keyframe"]
    start.click()
    expect(step).to_contain_text("Step 2 of 2: track both landmarks")
    expect(start).to_be_hidden()
    expect(page.locator("#submit")).to_be_enabled()

    goto_frame(page, LAST)
    assert point_states(page) == ["interpolated", "interpolated"]
    drag_image(page, top, (top[0] + shift[0], top[1] + shift[1]))
    drag_image(page, bottom, (bottom[0] + shift[0], bottom[1] + shift[1]))
    goto_frame(page, 7)
    page.locator('.point-row[data-point="1"]').click()
    page.keyboard.press("o")  # the lower landmark goes behind the hand
    goto_frame(page, 9)
    page.keyboard.press("o")
    goto_frame(page, 8)
    assert point_states(page) == ["interpolated", "occluded"]
    wait_saved(page)
    page.screenshot(path=str(output_dir / "object-annotated.png"))

    page.locator("#submit").click()
    confirm_submit(page.locator("#submit-dialog")).click()
    expect(page.locator("#banner")).to_have_text("Submitted. Thank you!")
    read = live_server.worker_get_task(link["token"])
    assert read["mode"] == "submitted"
    stored = server_keyframes(read["assignment"])
    assert [row[0] for row in stored[0]] == [0, LAST]
    assert [(row[0], row[3]) for row in stored[1]] == [(0, 1), (7, 0), (9, 1), (LAST, 1)]
    assert abs(stored[0][1][1] - (top[0] + shift[0])) <= 1
