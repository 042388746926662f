"""Rig health on the admin page in a real browser: the newest estimate's table names the camera
that is off (its row marked) and a hand shape that is off, adopting the refined version says
what became of the re-solve, and the imported calibration can be put back; screenshots at
1024x700 and 1440x900.

The version is stored directly with a report in the estimate's own form (backend/rig), so the
page is checked without waiting for an estimate on the live capture."""

from __future__ import annotations

import re
from pathlib import Path

from playwright.sync_api import Page, expect

from tests.browser.conftest import ADMIN_EMAIL, ADMIN_PASSWORD, LiveServer
from tests.browser.helpers import server_settings


def _store_version(server: LiveServer) -> list[str]:
    from backend.captures.service import sequence_cameras
    from backend.db import session_scope
    from backend.rig.service import store_version

    with server_settings(server), session_scope() as s:
        cameras = sequence_cameras(s, server.sequence_id)
        serials = [c.serial for c in cameras]
        entries = {c.serial: {"extrinsics": c.extrinsics, "time_offset_frames": 0,
                              "depth_scale": 1.0, "depth_shift_px": [0, 0]} for c in cameras}
        entries[serials[1]]["time_offset_frames"] = 1
        rows = [{"serial": serial, "view": v, "time_offset_frames": 0, "rotation_deg": 0.0,
                 "translation_mm": 0.0, "image_shift_px": 0.0, "residual_px_before": 2.7,
                 "residual_px_after": 2.7, "depth_scale_percent": 0.0,
                 "depth_shift_px": [0, 0], "faults": []} for v, serial in enumerate(serials)]
        rows[1].update(time_offset_frames=1, rotation_deg=0.46, translation_mm=4.9,
                       image_shift_px=6.1, residual_px_before=9.4, residual_px_after=2.6,
                       depth_scale_percent=1.0, depth_shift_px=[2, -3],
                       faults=["1 frame late",
                               ("pose off by 0.46 deg and 4.9 mm (the labelled points move "
                                "6.1 px)"), "depth scale +1.0 %",
                               "depth shifted by (2, -3) px against colour"])
        store_version(s, server.sequence_id, entries, {
            "labels": 2, "thresholds": {"image_shift_px": 0.8}, "cameras": rows,
            "faulty": [serials[1]],
            "hands": [{"index": 0, "side": "right", "calib_name": "subject_01_right",
                       "frames": 6, "bone_diff_median_mm": 2.04, "bone_diff_max_mm": 5.42,
                       "fitted_betas": [0.1] * 10,
                       "faults": [("hand shape off: its bones differ from the labelled ones "
                                   "by 2.0 mm (median of 20), up to 5.4 mm; 15 of 20 are "
                                   "longer")]}]})
    return serials


def test_rig_panel_names_the_camera_and_adopts_the_version(page: Page, live_server: LiveServer,
                                                          output_dir: Path) -> None:
    serials = _store_version(live_server)
    page.goto(f"{live_server.base}/admin/")
    page.locator("#login input[name=email]").fill(ADMIN_EMAIL)
    page.locator("#login input[name=password]").fill(ADMIN_PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#sequences-view")).to_be_visible()
    page.goto(f"{live_server.base}/admin/#/sequences/{live_server.sequence_id}")
    expect(page.locator("#rig-summary")).to_contain_text(f"cameras off: {serials[1]}.")
    expect(page.locator("#rig-rows tr")).to_have_count(len(serials))
    faulty = page.locator("#rig-rows tr.rig-faulty")
    expect(faulty).to_have_count(1)
    expect(faulty.locator("td").first).to_have_text(serials[1])
    expect(faulty).to_contain_text("1 frame late")
    expect(faulty).to_contain_text("+1.00 %")
    expect(page.locator("#rig-rows tr").first.locator("td").last).to_have_text("ok")
    hand = page.locator("#rig-hands li.rig-faulty")
    expect(hand).to_have_count(1)
    expect(hand).to_contain_text("Hand 0 right (mano_subject_01_right): shape off. Its bones "
                                 "differ from the labelled ones by 2.0 mm")
    expect(hand).to_contain_text("this version uses the shape fitted to the labels.")
    expect(page.locator("#rig-summary")).to_contain_text("The hand's shape is off.")
    page.locator("#rig-section").scroll_into_view_if_needed()
    for width, height in ((1024, 700), (1440, 900)):
        page.set_viewport_size({"width": width, "height": height})
        page.wait_for_timeout(150)
        page.locator("#rig-section").screenshot(
            path=str(output_dir / f"admin-rig-{width}x{height}.png"))
    page.locator("#rig-adopt").click()
    # The re-solve waits for accepted work, or is queued where other tests of this live server
    # left every task accepted.
    expect(page.locator("#rig-result")).to_have_text(re.compile(
        r"Version 1 in use; solve: (waiting: \d+ tasks? not accepted yet|solve run \d+ queued)"))
    expect(page.locator("#rig-summary")).to_contain_text("(version 1 is in use.)")
    expect(page.locator("#rig-adopt")).to_be_hidden()
    page.locator("#rig-imported").click()
    expect(page.locator("#rig-summary")).to_contain_text("the imported calibration is in use")
