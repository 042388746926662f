"""The annotation page's editing tools in the real page: copy the previous pose, drag the whole
skeleton or one finger, number keys, go to frame, hide and lock, the object outline check, the
labelled timeline, and every control within reach at 1024 x 700, 1366 x 768 and 1440 x 900."""

from __future__ import annotations

from pathlib import Path

import httpx
import numpy as np
import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import (
    Target,
    click_image,
    drag_image,
    modifier_drag,
    object_pixels,
    open_task,
    value_at,
    wait_saved,
    zoom_at,
    zoom_on_points,
)

VIEW = 1
LAST = CLIP_FRAMES - 1
# Index finger: MCP 5, PIP 6, DIP 7, tip 8 (DexYCB/MANO order).
INDEX_PIP = 6

# Writes a pose (21 x [x, y], image px) as keyframes at one frame, as one undo step.
SET_POSE = """([frame, pose]) => window.__dexlabel.store.setPose(frame,
  pose.map(([x, y], point) => ({ point, x, y, visible: true })))"""


def _open_hand(server: LiveServer, page: Page, worker: str) -> tuple[dict, dict]:
    task = server.task("hand", VIEW)
    link = server.assign(task, worker)
    open_task(page, server.page_url(link["token"], assignmentId=link["external_id"]))
    return task, link


def _pose(page: Target, frame: int) -> np.ndarray:
    """(21, 2) every point's value at ``frame`` as the store gives it."""
    values = page.evaluate("""(f) => Array.from({ length: 21 },
      (_, p) => window.__dexlabel.store.valueAt(p, f))""", frame)
    return np.array([[v["x"], v["y"]] for v in values], dtype=float)


def _keyframed(page: Page, frame: int) -> list[int]:
    return page.evaluate("""(f) => Array.from({ length: 21 }, (_, p) => p)
      .filter((p) => window.__dexlabel.store.keyframeAt(p, f) !== null)""", frame)


def _active(page: Page) -> int:
    return page.evaluate("window.__dexlabel.editor.active")


def _frame(page: Page) -> int:
    return page.evaluate("window.__dexlabel.editor.frame")


def _image_delta(page: Page, start, end) -> np.ndarray:
    """The image-px displacement a mouse moving between the screen positions of ``start`` and
    ``end`` makes (the page rounds nothing on the way)."""
    a = page.evaluate("([x, y]) => window.__dexlabel.editor.transform.toScreen(x, y)", list(start))
    b = page.evaluate("([x, y]) => window.__dexlabel.editor.transform.toScreen(x, y)", list(end))
    scale = page.evaluate("window.__dexlabel.editor.transform.scale")
    return np.array([b["x"] - a["x"], b["y"] - a["y"]]) / scale


def test_copy_previous_pose_copies_every_point_and_one_undo_reverts_it(
    live_server: LiveServer, page: Page
) -> None:
    task, _ = _open_hand(live_server, page, "W-tools-copy")
    truth = live_server.truth(task["serial"], 2)
    page.evaluate(SET_POSE, [2, truth.tolist()])
    page.keyboard.press("g")
    page.keyboard.type("6")
    page.keyboard.press("Enter")
    assert _frame(page) == 6
    assert _keyframed(page, 6) == []
    page.keyboard.press("c")
    expect(page.locator("#tool-message")).to_have_text("copied 21 points from frame 2")
    assert _keyframed(page, 6) == list(range(21))
    np.testing.assert_allclose(_pose(page, 6), np.round(truth, 2), atol=0.006)
    page.keyboard.press("Control+z")
    assert _keyframed(page, 6) == [], "one undo takes the whole copied pose back"
    assert _keyframed(page, 2) == list(range(21))
    page.locator("#copy-pose").click()  # the button does the same
    assert _keyframed(page, 6) == list(range(21))


def test_shift_drag_moves_the_skeleton_and_alt_drag_one_finger(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    task, _ = _open_hand(live_server, page, "W-tools-drag")
    truth = live_server.truth(task["serial"], 0)
    page.evaluate(SET_POSE, [0, truth.tolist()])
    zoom_on_points(page, truth)
    before = _pose(page, 0)

    # Shift+drag on the middle MCP: all 21 points move by the drag, one undo step.
    start = tuple(before[9])
    end = (start[0] + 14.0, start[1] - 9.0)
    delta = _image_delta(page, start, end)
    modifier_drag(page, "Shift", start, end)
    moved = _pose(page, 0)
    np.testing.assert_allclose(moved - before, np.tile(delta, (21, 1)), atol=0.05)
    page.keyboard.press("Control+z")
    np.testing.assert_allclose(_pose(page, 0), before, atol=1e-9)

    # Alt+drag on the index PIP: exactly the PIP, DIP and tip move.
    start = tuple(before[INDEX_PIP])
    end = (start[0] - 8.0, start[1] + 6.0)
    delta = _image_delta(page, start, end)
    modifier_drag(page, "Alt", start, end)
    after = _pose(page, 0)
    shifted = [p for p in range(21) if np.abs(after[p] - before[p]).max() > 1e-6]
    assert shifted == [6, 7, 8]
    np.testing.assert_allclose(after[6:9] - before[6:9], np.tile(delta, (3, 1)), atol=0.05)
    page.screenshot(path=str(output_dir / "tools-finger-drag.png"))
    page.keyboard.press("Control+z")

    # Ctrl+drag does the same (for desktops that keep Alt+drag for moving windows): the thumb
    # from its PIP.
    start = tuple(before[2])
    modifier_drag(page, "Control", start, (start[0] + 5.0, start[1] + 5.0))
    after = _pose(page, 0)
    assert [p for p in range(21) if np.abs(after[p] - before[p]).max() > 1e-6] == [2, 3, 4]


def test_number_keys_pick_joints_and_the_list_shows_each_key(
    live_server: LiveServer, page: Page
) -> None:
    _open_hand(live_server, page, "W-tools-keys")
    for keys, joint in [("3", 3), ("0", 10), ("Shift+4", 14), ("Shift+0", 20), ("w", 0),
                        ("9", 9)]:
        page.keyboard.press(keys)
        assert _active(page) == joint, keys
        expect(page.locator(".point-row.active")).to_have_attribute("data-point", str(joint))
    keys_shown = page.eval_on_selector_all(".point-key", "els => els.map((e) => e.textContent)")
    assert keys_shown[:3] == ["W", "1", "2"]
    assert keys_shown[10] == "0" and keys_shown[14] == "\u21e74" and keys_shown[20] == "\u21e70"
    # A first placement hands over to the next unplaced point that is not hidden.
    page.keyboard.press("w")
    page.locator('.point-item[data-point="1"] .point-hide').click()
    click_image(page, 300, 200)
    assert _active(page) == 2
    page.locator("#show-shortcuts").click()
    shortcuts = page.locator("#shortcut-list")
    expect(shortcuts).to_contain_text("Shift + drag a point")
    expect(shortcuts).to_contain_text("Alt + drag or Ctrl + drag")
    expect(shortcuts).to_contain_text("pick joint 11-19")


def test_go_to_frame_goes_there_and_refuses_a_frame_outside_the_clip(
    live_server: LiveServer, page: Page
) -> None:
    _open_hand(live_server, page, "W-tools-goto")
    page.keyboard.press("g")
    expect(page.locator("#goto-frame")).to_be_focused()
    page.keyboard.type("7")
    page.keyboard.press("Enter")
    assert _frame(page) == 7
    expect(page.locator("#frame-label")).to_have_text(f"Frame 7 / {LAST}")
    expect(page.locator("#goto-frame")).not_to_be_focused()
    page.keyboard.press("g")
    page.keyboard.type("9999")
    page.keyboard.press("Enter")
    expect(page.locator("#goto-error")).to_have_text(
        f"frame 9999 is not in this clip (frames are 0-{LAST})")
    assert _frame(page) == 7
    page.locator("#goto-frame").fill("abc")
    page.locator("#goto-go").click()
    expect(page.locator("#goto-error")).to_contain_text('"abc" is not a frame number')
    page.locator("#goto-frame").fill("0")
    page.locator("#goto-frame").press("Enter")
    assert _frame(page) == 0
    expect(page.locator("#goto-error")).to_be_hidden()


def _drawn_rgb(page: Page, x: float, y: float) -> list[int]:
    """The canvas's colour at an image position (what is drawn there now)."""
    return page.evaluate("""([x, y]) => {
      const e = window.__dexlabel.editor;
      const s = e.transform.toScreen(x, y);
      const dpr = window.devicePixelRatio || 1;
      return [...e.ctx.getImageData(Math.round(s.x * dpr), Math.round(s.y * dpr), 1, 1).data]
        .slice(0, 3);
    }""", [x, y])


def test_hidden_points_are_not_drawn_or_grabbed_and_locked_points_do_not_move(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    task, link = _open_hand(live_server, page, "W-tools-hide")
    truth = live_server.truth(task["serial"], 0)
    page.evaluate(SET_POSE, [0, truth.tolist()])
    zoom_on_points(page, truth)
    page.keyboard.press("w")  # the wrist is active; the index tip (8) is drawn as a disc
    tip = tuple(_pose(page, 0)[8])
    green = [0x31, 0xA3, 0x54]  # the index finger's colour
    assert np.abs(np.array(_drawn_rgb(page, *tip)) - green).max() <= 2
    page.locator('.point-item[data-point="8"] .point-hide').click()
    expect(page.locator('.point-item[data-point="8"]')).to_have_attribute("data-hidden", "true")
    assert np.abs(np.array(_drawn_rgb(page, *tip)) - green).max() > 30, "hidden: not drawn"
    # Closer in, so that no other joint lies within grabbing reach (10 screen px) of the tip.
    zoom_at(page, *tip, -300)
    before = _pose(page, 0)
    drag_image(page, tip, (tip[0] + 10, tip[1] + 10))
    np.testing.assert_array_equal(_pose(page, 0), before)  # nothing grabbed, nothing placed
    zoom_at(page, *tip, 300)  # back out about the same spot: the whole hand in view again

    # H hides and shows the active point.
    page.keyboard.press("5")
    page.keyboard.press("h")
    expect(page.locator('.point-item[data-point="5"]')).to_have_attribute("data-hidden", "true")
    page.keyboard.press("h")
    expect(page.locator('.point-item[data-point="5"]')).to_have_attribute("data-hidden", "false")

    # A locked point stays put under a plain drag and a skeleton drag; the rest move.
    page.locator('.point-item[data-point="12"] .point-lock').click()
    middle_tip = tuple(before[12])
    drag_image(page, middle_tip, (middle_tip[0] + 12, middle_tip[1]))
    expect(page.locator("#tool-message")).to_contain_text("12 Middle tip is locked")
    np.testing.assert_array_equal(_pose(page, 0), before)
    start = tuple(before[0])
    modifier_drag(page, "Shift", start, (start[0] + 10, start[1] + 4))
    after = _pose(page, 0)
    still = [p for p in range(21) if np.abs(after[p] - before[p]).max() < 1e-6]
    assert still == [12]
    page.screenshot(path=str(output_dir / "tools-hide-lock.png"))

    # View settings: kept in this browser across a reload, never sent to the server.
    wait_saved(page)
    page.reload()
    page.wait_for_function("window.__dexlabel.ready")
    expect(page.locator('.point-item[data-point="8"]')).to_have_attribute("data-hidden", "true")
    expect(page.locator('.point-item[data-point="12"]')).to_have_attribute("data-locked", "true")
    saved = live_server.worker_get_task(link["token"])["assignment"]["tracks"]
    assert "hidden" not in str(saved) and "locked" not in str(saved)


def test_object_landmark_off_the_highlight_is_refused_and_blocks_submit(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    task = live_server.task("object", VIEW)
    highlight = task["highlight"]
    assert highlight["frame"] == 0 and highlight["label"]
    polygon = np.array(highlight["polygon"])
    link = live_server.assign(task, "W-tools-object")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    pixels = object_pixels(live_server, task["serial"], 0)
    centre = pixels.mean(axis=0)
    outside = (polygon[:, 0].max() + 25, centre[1])
    click_image(page, *outside)
    message = (f"landmark 1 at frame 0 is outside the highlighted {highlight['label']}; "
               "place it on the object")
    expect(page.locator("#tool-message")).to_have_text(message)
    assert page.evaluate("window.__dexlabel.store.keyframes(0).length") == 0
    page.screenshot(path=str(output_dir / "tools-object-refused.png"))
    top = (centre[0], pixels[:, 1].min() + 6)
    click_image(page, *top)
    v = value_at(page, 0, 0)
    assert abs(v["x"] - top[0]) < 1 and abs(v["y"] - top[1]) < 1

    # An older save with a landmark off the object: Submit lists it and refuses.
    bottom = (centre[0], pixels[:, 1].max() - 6)
    off = [polygon[:, 0].max() + 30, polygon[:, 1].min() - 5]
    stale = {"version": page.evaluate("window.__dexlabel.store.version"), "tracks": [
        {"point": 0, "keyframes": [[0, *top, 1], [LAST, *top, 1]]},
        {"point": 1, "keyframes": [[0, *off, 1], [LAST, *bottom, 1]]}]}
    wait_saved(page)
    stale["version"] = live_server.worker_get_task(link["token"])["assignment"]["version"]
    resp = httpx.put(f"{live_server.base}/api/annotate/tracks", json=stale, timeout=30,
                     headers={"Authorization": f"Bearer {link['token']}"})
    assert resp.status_code == 200, resp.text
    page.reload()
    page.wait_for_function("window.__dexlabel.ready")
    expect(page.locator("#submit")).to_be_enabled()
    page.locator("#submit").click()
    box = page.locator("#tool-message")
    expect(box).to_contain_text("Cannot submit")
    expect(box).to_contain_text(f"landmark 2 at frame 0 is outside the highlighted "
                                f"{highlight['label']}")
    expect(page.locator("#submit-dialog")).not_to_be_visible()
    page.screenshot(path=str(output_dir / "tools-object-submit-refused.png"))
    drag_image(page, tuple(off), bottom)
    v = value_at(page, 1, 0)
    assert abs(v["x"] - bottom[0]) < 1.5 and abs(v["y"] - bottom[1]) < 1.5
    page.locator("#submit").click()
    expect(page.locator("#submit-dialog")).to_be_visible()


CONTROLS = ["#undo", "#redo", "#toggle-instructions", "#show-shortcuts", "#submit",
            "#toggle-occluded", "#next-point", "#delete-keyframe", "#copy-pose", "#back10",
            "#back1", "#play", "#fwd1", "#fwd10", "#fps", "#goto-frame", "#goto-go",
            "#timeline"]


def _inside_viewport(page: Page, selector: str) -> None:
    box = page.locator(selector).bounding_box()
    size = page.viewport_size
    assert box is not None and size is not None, selector
    assert box["x"] >= 0 and box["y"] >= 0, (selector, box)
    assert box["x"] + box["width"] <= size["width"] + 0.5, (selector, box, size)
    assert box["y"] + box["height"] <= size["height"] + 0.5, (selector, box, size)


@pytest.mark.parametrize(("width", "height"), [(1024, 700), (1366, 768), (1440, 900)])
def test_every_control_is_within_reach(
    live_server: LiveServer, page: Page, output_dir: Path, width: int, height: int
) -> None:
    page.set_viewport_size({"width": width, "height": height})
    task, _ = _open_hand(live_server, page, f"W-tools-layout-{width}")
    truth = live_server.truth(task["serial"], 0)
    page.evaluate(SET_POSE, [0, truth.tolist()])
    page.evaluate(SET_POSE, [LAST, live_server.truth(task["serial"], LAST).tolist()])
    page.evaluate("window.__dexlabel.store.toggleVisibility(4, 5)")
    assert page.evaluate("document.documentElement.scrollWidth") <= width
    for selector in CONTROLS:
        _inside_viewport(page, selector)
    view = page.locator("#view").bounding_box()
    assert view is not None and view["width"] >= 0.55 * width and view["height"] >= 0.5 * height
    # The point list scrolls inside its panel; its last joints come into view there.
    for p in (19, 20):
        page.locator(f'.point-row[data-point="{p}"]').scroll_into_view_if_needed()
        _inside_viewport(page, f'.point-row[data-point="{p}"]')
        _inside_viewport(page, f'.point-item[data-point="{p}"] .point-lock')
    # Timeline rows are tall enough to click; the active point's row scrolls into view, and a
    # click on it selects that point and frame.
    row = page.evaluate("window.__dexlabel.page.timeline.rowHeight")
    assert row >= 14
    for active, other in [(20, 19), (0, 1)]:
        page.keyboard.press("Shift+0" if active == 20 else "w")
        for p in (active, other):
            centre = page.evaluate("([p]) => window.__dexlabel.page.timeline.cellCentre(p, 3)",
                                   [p])
            canvas = page.locator(".timeline-canvas").bounding_box()
            timeline = page.locator("#timeline").bounding_box()
            assert canvas is not None and timeline is not None
            y = canvas["y"] + centre["y"]
            # Below the frame numbers, which stay at the top of the timeline (14 px).
            top, bottom = timeline["y"] + 14 - 0.5, timeline["y"] + timeline["height"] + 0.5
            assert top <= y - row / 2 <= y + row / 2 <= bottom, (p, y, timeline)
        page.mouse.click(canvas["x"] + centre["x"], y)  # the other row, at frame 3
        assert _active(page) == other and _frame(page) == 3
    page.screenshot(path=str(output_dir / f"tools-hand-{width}x{height}.png"))
    toggle = page.locator("#toggle-instructions")
    if toggle.get_attribute("aria-pressed") == "false":  # narrow windows start with them shut
        toggle.click()
    _inside_viewport(page, "#instructions")
    page.screenshot(path=str(output_dir / f"tools-hand-{width}x{height}-instructions.png"))


def test_timeline_draws_keyframe_markers_by_source(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    """A keyframe's source decides its marker in the timeline row: the four markers drawn for
    one point differ pixel by pixel, the placed one is a diamond (its bounding square's corners
    empty) and a keyframe without a source is drawn as placed."""
    task = live_server.task("object", 0)
    link = live_server.assign(task, "W-tools-markers")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    x, y = np.mean(task["highlight"]["polygon"], axis=0).tolist()
    page.evaluate("""([x, y]) => window.__dexlabel.store.setKeyframes(0, [
      { frame: 0, x, y, visible: true },
      { frame: 3, x, y, visible: true, source: "tracked" },
      { frame: 6, x, y, visible: true, source: "prefilled" },
      { frame: 9, x, y, visible: true, source: "edited" }])""", [x, y])
    masks = page.evaluate("""() => {
      const t = window.__dexlabel.page.timeline;
      const ctx = t.canvas.getContext("2d");
      const dpr = window.devicePixelRatio || 1;
      const r = Math.max(3, Math.min(t.rowHeight / 2 - 1, t.cellWidth / 2));
      return [0, 3, 6, 9].map((f) => {
        const c = t.cellCentre(0, f);
        const cy = 14 + (t.rowHeight - 2) / 2;  // the marker's centre line in row 0
        const n = Math.ceil(2 * r * dpr);
        const data = ctx.getImageData(Math.round((c.x - r) * dpr), Math.round((cy - r) * dpr),
          n, n).data;
        const mask = [];
        for (let i = 0; i < data.length; i += 4) {
          // Filled in the landmark's orange (#ff7f0e) or not.
          mask.push(Math.abs(data[i] - 255) + Math.abs(data[i + 1] - 127) +
            Math.abs(data[i + 2] - 14) < 60 ? 1 : 0);
        }
        return { n, mask };
      });
    }""")
    arrays = [np.array(m["mask"]).reshape(m["n"], m["n"]) for m in masks]
    for a in arrays:
        assert a.sum() > 0.3 * a.size, "a filled marker"
    for i in range(4):
        for j in range(i + 1, 4):
            assert np.abs(arrays[i] - arrays[j]).sum() >= 12, ("markers alike", i, j)
    placed = arrays[0]
    k = max(1, placed.shape[0] // 5)
    assert placed[:k, :k].sum() == placed[:k, -k:].sum() == placed[-k:, :k].sum() == 0
    rows = page.evaluate("window.__dexlabel.store.toJSON().tracks[0].keyframes")
    assert [len(r) for r in rows] == [4, 5, 5, 5], "placed is the default, written as 4 values"
    page.screenshot(path=str(output_dir / "tools-timeline-sources.png"))


# A host page that frames the annotation page as the portal and MTurk do: a bar above, the
# frame below it filling the rest of the window, with the portal's sandbox.
HOST = """<!doctype html><html><body style="margin:0;overflow:hidden">
<div style="height:72px;background:#ddd">HIT: track the hand</div>
<iframe id="hit" src="{src}" title="HIT" style="display:block;width:calc(100vw - 18px);
  margin:0 9px;height:calc(100vh - 80px);border:1px solid #999;box-sizing:border-box"
  sandbox="allow-scripts allow-forms allow-same-origin allow-top-navigation-by-user-activation">
</iframe></body></html>"""


RECT = "e => { const r = e.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom] }"


@pytest.mark.parametrize(("width", "height"), [(1024, 700), (1366, 768)])
def test_framed_page_keeps_controls_in_reach_and_modifier_drags_work(
    live_server: LiveServer, page: Page, output_dir: Path, width: int, height: int
) -> None:
    page.set_viewport_size({"width": width, "height": height})
    task = live_server.task("hand", VIEW)
    link = live_server.assign(task, f"W-tools-frame-{width}")
    src = live_server.page_url(link["token"], assignmentId=link["external_id"])
    host = f"{live_server.base}/tools-host.html"
    page.route(host, lambda route: route.fulfill(
        content_type="text/html", body=HOST.replace("{src}", src)))
    page.goto(host)
    frame = page.frame_locator("#hit")
    inner = page.frame(url=lambda u: "/annotate/" in u)
    assert inner is not None
    inner.wait_for_function("window.__dexlabel && window.__dexlabel.ready")
    size = inner.evaluate("[innerWidth, innerHeight, document.documentElement.scrollWidth]")
    assert size[2] <= size[0], "no sideways scrolling inside the frame"
    for selector in CONTROLS:
        box = inner.locator(selector).evaluate(RECT)
        inside = box[0] >= 0 and box[1] >= 0 and box[2] <= size[0] + 0.5
        assert inside and box[3] <= size[1] + 0.5, (selector, box, size)
    truth = live_server.truth(task["serial"], 0)
    inner.evaluate(SET_POSE, [0, truth.tolist()])
    zoom_on_points(inner, truth)
    before = _pose(inner, 0)
    for modifier, joint, moved in [("Shift", 9, list(range(21))), ("Alt", INDEX_PIP, [6, 7, 8])]:
        start = tuple(before[joint])
        page.keyboard.down(modifier)
        drag_image(inner, start, (start[0] + 9.0, start[1] + 7.0))
        page.keyboard.up(modifier)
        after = _pose(inner, 0)
        assert [p for p in range(21) if np.abs(after[p] - before[p]).max() > 1e-6] == moved
        inner.evaluate("window.__dexlabel.store.undo()")
    expect(frame.locator("#submit")).to_be_visible()
    page.screenshot(path=str(output_dir / f"tools-framed-{width}x{height}.png"))


def test_object_task_controls_are_within_reach_at_1024x700(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    page.set_viewport_size({"width": 1024, "height": 700})
    task = live_server.task("object", VIEW)
    link = live_server.assign(task, "W-tools-object-layout")
    open_task(page, live_server.page_url(link["token"], assignmentId=link["external_id"]))
    expect(page.locator("#step-banner")).to_be_visible()
    assert page.evaluate("document.documentElement.scrollWidth") <= 1024
    for selector in [*CONTROLS, "#start-tracking", '.point-item[data-point="1"] .point-lock']:
        _inside_viewport(page, selector)
    expect(page.locator("#drag-hint")).to_have_text("Shift+drag a landmark: both move together.")
    # Landmarks go by name, picked with keys 1 and 2 (no 0-based number beside "Landmark 1").
    names = page.eval_on_selector_all(".point-name", "els => els.map((e) => e.textContent)")
    keys = page.eval_on_selector_all(".point-key", "els => els.map((e) => e.textContent)")
    assert names == ["Landmark 1", "Landmark 2"] and keys == ["1", "2"]
    assert page.evaluate("window.__dexlabel.page.timeline.rowHeight") >= 14
    page.screenshot(path=str(output_dir / "tools-object-1024x700.png"))
