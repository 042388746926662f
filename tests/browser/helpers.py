"""Driving the annotation page like a worker: open, click and drag on image positions, read back.

Image positions are converted to page coordinates by the page's own Transform, so clicks land
where a worker's would at the current zoom. Every helper also takes the page's Frame when it is
framed (as the worker portal frames it, like MTurk): positions are then offset by the iframe.
"""

from __future__ import annotations

import hashlib
import time
from typing import Any

from playwright.sync_api import Frame, Page, expect

Target = Page | Frame

READY = "window.__dexlabel && (window.__dexlabel.ready || window.__dexlabel.error)"


def _page_of(target: Target) -> Page:
    """The top-level page, whose mouse and keyboard reach into a framed annotation page."""
    return target.page if isinstance(target, Frame) else target


def open_task(page: Page, url: str) -> None:
    """Opens the page and waits until every frame is loaded (or an error is shown)."""
    page.goto(url)
    page.wait_for_function(READY)


def frames_shown(page: Page) -> bool:
    """Every frame decoded, and the canvas shows the image (not the empty background)."""
    return page.evaluate("""() => {
      const { editor } = window.__dexlabel;
      if (editor.bitmaps.filter(Boolean).length !== editor.numFrames) return false;
      const r = editor.transform.imageRect(editor.task.width, editor.task.height);
      const dpr = window.devicePixelRatio || 1;
      const x = Math.max(0, r.x) + 4, y = Math.max(0, r.y) + 4;
      const [red, green, blue] = editor.ctx.getImageData(x * dpr, y * dpr, 1, 1).data;
      return !(red === 0x1b && green === 0x1f && blue === 0x24);
    }""")


def to_client(page: Target, x: float, y: float) -> tuple[float, float]:
    pos = page.evaluate("([x, y]) => window.__dexlabel.imageToClient(x, y)", [x, y])
    if isinstance(page, Frame) and page.parent_frame is not None:
        box = page.frame_element().bounding_box()
        assert box is not None
        return box["x"] + pos["x"], box["y"] + pos["y"]
    return pos["x"], pos["y"]


def click_image(page: Target, x: float, y: float) -> None:
    _page_of(page).mouse.click(*to_client(page, x, y))


def drag_image(page: Target, start: tuple[float, float], end: tuple[float, float]) -> None:
    """Presses on ``start`` (image px), moves in steps to ``end``, releases."""
    mouse = _page_of(page).mouse
    mouse.move(*to_client(page, *start))
    mouse.down()
    mouse.move(*to_client(page, *end), steps=6)
    mouse.up()


def zoom_at(page: Target, x: float, y: float, wheel_delta: float) -> None:
    """Wheel over an image position (negative delta zooms in)."""
    mouse = _page_of(page).mouse
    mouse.move(*to_client(page, x, y))
    mouse.wheel(0, wheel_delta)


def pan_to_centre(page: Target, x: float, y: float) -> None:
    """Right-drags the image so that image position (x, y) sits in the middle of the canvas."""
    box = page.locator("#view").bounding_box()
    mouse = _page_of(page).mouse
    mouse.move(*to_client(page, x, y))
    mouse.down(button="right")
    mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2, steps=5)
    mouse.up(button="right")


def zoom_on_points(page: Target, points) -> None:
    """Centres the image on the mean of ``points`` (N x 2, image px) and zooms in on it."""
    cx = sum(p[0] for p in points) / len(points)
    cy = sum(p[1] for p in points) / len(points)
    pan_to_centre(page, cx, cy)
    zoom_at(page, cx, cy, -400)


def place_joints(page: Target, joints, points) -> None:
    """One click per point, in order; the page moves on to the next unplaced point itself."""
    for p in points:
        expect(page.locator(f'.point-row[data-point="{p}"]')).to_have_class("point-row active")
        click_image(page, *joints[p])


def goto_frame(page: Target, frame: int) -> None:
    """Steps there with the keyboard (Shift+arrows by 10, arrows by 1)."""
    current = page.evaluate("window.__dexlabel.editor.frame")
    delta = frame - current
    key = "ArrowRight" if delta > 0 else "ArrowLeft"
    for _ in range(abs(delta) // 10):
        _page_of(page).keyboard.press(f"Shift+{key}")
    for _ in range(abs(delta) % 10):
        _page_of(page).keyboard.press(key)
    assert page.evaluate("window.__dexlabel.editor.frame") == frame


def select_point(page: Page, point: int) -> None:
    page.locator(f'.point-row[data-point="{point}"]').click()


def point_states(page: Target) -> list[str]:
    """Each point's state in the current frame, as the point list shows it."""
    return page.eval_on_selector_all(".point-row", "rows => rows.map((r) => r.dataset.state)")


def value_at(page: Page, point: int, frame: int) -> dict[str, Any]:
    return page.evaluate("([p, f]) => window.__dexlabel.store.valueAt(p, f)", [point, frame])


def wait_saved(page: Target) -> None:
    expect(page.locator("#save-status")).to_have_text("All changes saved", timeout=10000)


def server_keyframes(assignment: dict) -> dict[int, list[list]]:
    """Keyframes per point as the server holds them (from GET /api/annotate/task)."""
    tracks = assignment["tracks"]
    return {t["point"]: t["keyframes"] for t in tracks["tracks"]} if tracks else {}


def assert_rows_close(got: list[list], want: list[list], tol: float = 1.0) -> None:
    """Keyframe rows equal, positions within ``tol`` image px (clicks land on whole screen px)."""
    assert len(got) == len(want), (got, want)
    for g, w in zip(got, want, strict=True):
        assert g[0] == w[0] and g[3] == w[3], (got, want)
        assert abs(g[1] - w[1]) <= tol and abs(g[2] - w[2]) <= tol, (got, want)


# The admin page's overlay <img>: [SHA-256 of its blob, natural width, height], or null while
# it loads.
_SHOWN_PNG = """async () => {
  const img = document.getElementById("overlay-image");
  if (!img.src.startsWith("blob:") || !img.complete || !img.naturalWidth) return null;
  let bytes;
  try {  // the page revokes a picture's URL when the next one arrives
    bytes = await (await fetch(img.src)).arrayBuffer();
  } catch {
    return null;
  }
  const digest = new Uint8Array(await crypto.subtle.digest("SHA-256", bytes));
  const hex = Array.from(digest, (b) => b.toString(16).padStart(2, "0")).join("");
  return [hex, img.naturalWidth, img.naturalHeight];
}"""


def wait_overlay_shows(page: Page, png: bytes, timeout_s: float = 30.0) -> None:
    """Until the admin page's overlay shows exactly ``png`` (byte for byte, at its size)."""
    want = [hashlib.sha256(png).hexdigest(), int.from_bytes(png[16:20], "big"),
            int.from_bytes(png[20:24], "big")]
    deadline = time.monotonic() + timeout_s
    while page.evaluate(_SHOWN_PNG) != want and time.monotonic() < deadline:
        time.sleep(0.1)
    assert page.evaluate(_SHOWN_PNG) == want
