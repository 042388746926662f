"""Driving the annotation page like a worker: open, click and drag on image positions, read back.

Image positions are converted to page coordinates by the page's own Transform, so clicks land
where a worker's would at the current zoom. Every helper also takes the page's Frame when it is
framed (as the worker portal frames it, like MTurk): positions are then offset by the iframe.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest
from playwright.sync_api import Frame, Page, expect

from tests.conftest import reset_caches

if TYPE_CHECKING:
    from tests.browser.conftest import LiveServer

Target = Page | Frame

@contextmanager
def queue_worker(server: LiveServer, log: Path) -> Iterator[None]:
    """A `dexlabel worker` process on the live server's database and queue while the block
    runs (its output in ``log``)."""
    with log.open("w") as log_file:
        proc = subprocess.Popen([sys.executable, "-m", "backend.cli", "worker", "--workers", "1"],
                                env={**os.environ, **server.env},
                                stdout=log_file, stderr=subprocess.STDOUT)
        try:
            yield
        finally:
            proc.terminate()
            proc.wait(timeout=20)


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


def step_through(page: Target, first: int, last: int) -> None:
    """Goes to ``first``, then steps one frame at a time (arrow keys) to ``last``: every frame
    between is shown, as a worker checking proposals would see them."""
    goto_frame(page, first)
    key = "ArrowRight" if last >= first else "ArrowLeft"
    for _ in range(abs(last - first)):
        _page_of(page).keyboard.press(key)
    assert page.evaluate("window.__dexlabel.editor.frame") == last


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


@contextmanager
def server_settings(server: LiveServer) -> Iterator[None]:
    """This process reads the live server's settings (database, storage, keys) inside."""
    with pytest.MonkeyPatch.context() as mp:
        for key, value in server.env.items():
            mp.setenv(key, value)
        reset_caches()
        try:
            yield
        finally:
            reset_caches()


def check_cells(server: LiveServer, assignment_id: int, num_points: int,
                num_frames: int) -> set[tuple[int, int]]:
    """The assignment's check cells (point, frame): where any suggestion is shown 15 px off."""
    from backend.config import get_settings
    from worker.assist import checks

    with server_settings(server):
        key = checks.check_key(get_settings().signing_key)
    return set(checks.check_cells(key, assignment_id, num_points, num_frames))


def best_tracked_joint(server: LiveServer, token: str, truth: list[np.ndarray],
                       tol_px: float) -> int:
    """The hand joint the tracker follows best from true keyframes at the clip's ends, asked
    for one joint at a time as the page's Track does (on a short clip the hand moves fast from
    frame to frame, and most joints hold at a few frames only): the most proposals within
    ``tol_px`` of the truth. truth: per frame (21, 2) image px."""
    last = len(truth) - 1

    def held(p: int) -> int:
        rows = [[f, *truth[f][p].round(2).tolist(), 1] for f in (0, last)]
        resp = httpx.post(f"{server.base}/api/annotate/proposals",
                          json={"tracks": [{"point": p, "keyframes": rows}]},
                          headers={"Authorization": f"Bearer {token}"}, timeout=60)
        assert resp.status_code == 200, resp.text
        found = resp.json()["points"][0]
        return sum(1 for f, (xy, ok) in enumerate(zip(found["xy"], found["ok"], strict=True))
                   if ok and np.hypot(*(np.array(xy) - truth[f][p])) < tol_px)
    counts = [held(p) for p in range(21)]
    assert max(counts) >= 3, counts
    return int(np.argmax(counts))


def grab_and_drop(page: Page, start: tuple[float, float], end: tuple[float, float]) -> None:
    """Grabs the point at ``start`` (image px), swings out and drops it at ``end``: a drag
    however close the two are."""
    mouse = page.mouse
    sx, sy = to_client(page, *start)
    ex, ey = to_client(page, *end)
    mouse.move(sx, sy)
    mouse.down()
    mouse.move(sx + 30, sy + 30, steps=4)
    mouse.move(ex, ey, steps=4)
    mouse.up()


def modifier_drag(page: Page, modifier: str, start: tuple[float, float],
                  end: tuple[float, float]) -> None:
    """A drag from image position ``start`` to ``end`` with ``modifier`` held throughout."""
    page.keyboard.down(modifier)
    drag_image(page, start, end)
    page.keyboard.up(modifier)


def screens(page: Page, output_dir: Path, name: str, sizes: list[tuple[int, int]],
            back_to: dict[str, int]) -> None:
    """Screenshots ``{name}-{w}x{h}.png`` at each size (instructions folded away, as a worker
    who knows the task has them), then back to the viewport ``back_to``."""
    if page.get_attribute("#toggle-instructions", "aria-pressed") == "true":
        page.click("#toggle-instructions")
    for width, height in sizes:
        page.set_viewport_size({"width": width, "height": height})
        page.wait_for_timeout(150)  # the canvas follows its box on the next resize callback
        page.screenshot(path=str(output_dir / f"{name}-{width}x{height}.png"))
    page.set_viewport_size(back_to)
    page.wait_for_timeout(150)


def object_pixels(server: LiveServer, serial: str, frame: int) -> np.ndarray:
    """(N, 2) x, y of the object's pixels in the ground-truth segmentation."""
    folder = next(server.capture.glob(f"*/*/{serial}"))
    seg = np.load(folder / f"labels_{frame:06d}.npz")["seg"]
    labels = [v for v in np.unique(seg) if v not in (0, 255)]  # 0: background, 255: the hand
    ys, xs = np.nonzero(seg == labels[0])
    return np.stack([xs, ys], axis=1).astype(float)


def confirm_submit(dialog: Any) -> Any:
    """The submit dialog's confirm button once the page's image check has answered, with any
    warnings it (or the local checks) raised confirmed, as a worker who read them does."""
    from playwright.sync_api import expect

    expect(dialog).to_have_attribute("data-image-check", "done")
    box = dialog.locator(".confirm-warnings input")
    if box.is_visible():
        box.check()
    return dialog.locator(".submit-confirm")
