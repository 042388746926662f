"""What a worker new to the annotation page meets first: the header names the camera by its
number and the hand by its side, the keys work before any click (Home/End included), a reload
reopens the frame the worker was on, and the banner about another tab's save goes once a later
save succeeds."""

from __future__ import annotations

import json
import time
from pathlib import Path

from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import READY, click_image, open_task, wait_saved

LAST = CLIP_FRAMES - 1


def _hand_task(server: LiveServer, worker: str) -> tuple[dict, dict]:
    task = server.task("hand", 0)
    return task, server.assign(task, worker)


def test_the_header_names_the_camera_by_number_and_the_instructions_the_hand_by_side(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    task, link = _hand_task(live_server, "W-newcomer-header")
    open_task(page, live_server.page_url(link["token"]))
    title = page.locator("#task-title")
    number = sorted(t["serial"] for t in live_server.tasks).index(task["serial"]) + 1
    assert (task["view_number"], task["num_views"]) == (number, 2)
    expect(title).to_have_text(f"Right hand: 21 joints · camera {number} of 2 · "
                               f"{CLIP_FRAMES} frames")
    expect(title).to_have_attribute("title", f"camera serial {task['serial']}")
    intro = page.locator("#instructions p").first
    expect(intro).to_contain_text("Track the 21 joints of the right hand")
    expect(page.locator("#instructions")).not_to_contain_text("highlighted hand")
    expect(page.locator("#shortcut-list")).to_contain_text("first / last frame")
    for width, height in [(1440, 900), (1024, 700)]:
        page.set_viewport_size({"width": width, "height": height})
        page.wait_for_timeout(150)
        page.screenshot(path=str(output_dir / f"newcomer-annotate-{width}x{height}.png"))


def test_the_keys_step_frames_without_a_click_and_home_end_go_to_the_ends(
    live_server: LiveServer, page: Page
) -> None:
    _, link = _hand_task(live_server, "W-newcomer-keys")
    open_task(page, live_server.page_url(link["token"]))
    assert page.evaluate("document.activeElement.id") == "view"
    ring = page.evaluate(
        "getComputedStyle(document.querySelector('#stage'), '::after').borderTopWidth")
    assert ring == "2px", ring
    frame = "window.__dexlabel.editor.frame"
    page.keyboard.press("ArrowRight")
    assert page.evaluate(frame) == 1
    page.keyboard.press("End")
    assert page.evaluate(frame) == LAST
    expect(page.locator("#frame-label")).to_have_text(f"Frame {LAST} / {LAST}")
    page.keyboard.press("Home")
    assert page.evaluate(frame) == 0
    # Focus left on a button (a click on one) comes back to the canvas with Tab order intact:
    # the canvas takes focus like any control.
    page.locator("#view").focus()
    assert page.evaluate("document.activeElement.tabIndex") == 0


def test_a_reload_reopens_the_frame_the_worker_was_on(live_server: LiveServer,
                                                      page: Page) -> None:
    _, link = _hand_task(live_server, "W-newcomer-reload")
    open_task(page, live_server.page_url(link["token"]))
    for _ in range(7):
        page.keyboard.press("ArrowRight")
    assert page.evaluate("window.__dexlabel.editor.frame") == 7
    page.reload()
    page.wait_for_function(READY)
    assert page.evaluate("window.__dexlabel.editor.frame") == 7
    expect(page.locator("#frame-label")).to_have_text(f"Frame 7 / {LAST}")
    # Another assignment in the same tab starts at its own first frame.
    _, other = _hand_task(live_server, "W-newcomer-reload-2")
    page.goto("about:blank")
    open_task(page, live_server.page_url(other["token"]))
    assert page.evaluate("window.__dexlabel.editor.frame") == 0


def test_the_other_tab_banner_goes_once_a_later_save_succeeds(live_server: LiveServer,
                                                             page: Page) -> None:
    task, link = _hand_task(live_server, "W-newcomer-stale")
    open_task(page, live_server.page_url(link["token"]))
    centre = (task["width"] / 2, task["height"] / 2)
    version = page.evaluate("window.__dexlabel.store.version")
    click_image(page, *centre)
    assert page.evaluate("window.__dexlabel.saver.unsaved") == 1
    page.wait_for_function(f"window.__dexlabel.store.version === {version + 1} && "
                           "window.__dexlabel.saver.unsaved === 0")
    # Unsaved work this browser kept from before that save (as a second tab leaves it).
    stale = {"baseVersion": version, "tracks": [], "unsaved": 2, "editCount": 1, "workingTime": 1.0,
             "savedAt": int(time.time() * 1000)}
    page.evaluate("([key, record]) => localStorage.setItem(key, record)",
                  [f"dexlabel:annotate:{link['assignment_id']}", json.dumps(stale)])
    page.reload()
    page.wait_for_function(READY)
    banner = page.locator("#banner")
    expect(banner).to_be_visible()
    expect(banner).to_contain_text("older than the saved version")
    page.keyboard.press("ArrowRight")
    click_image(page, centre[0] + 20, centre[1])
    expect(banner).to_be_visible()  # until that edit is saved
    page.wait_for_function(f"window.__dexlabel.store.version === {version + 2}")
    wait_saved(page)
    expect(banner).to_be_hidden()
