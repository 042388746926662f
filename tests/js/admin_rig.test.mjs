// The rig-health panel's pure helpers: one row of cells per camera and the summary sentence.
import assert from "node:assert/strict";
import { test } from "node:test";

import { rigHandLines, rigRows, rigSummary } from "../../frontend/admin/core/rig-format.js";

const report = {
  version: 2, labels: 48, faulty: ["cam-3"],
  cameras: [
    { serial: "cam-0", time_offset_frames: 0, rotation_deg: 0, translation_mm: 0,
      image_shift_px: 0, residual_px_before: 2.71, residual_px_after: 2.7,
      depth_scale_percent: 0, depth_shift_px: [0, 0], faults: [] },
    { serial: "cam-3", time_offset_frames: 1, rotation_deg: 0.456, translation_mm: 4.04,
      image_shift_px: 6.3, residual_px_before: 9.1, residual_px_after: 2.6,
      depth_scale_percent: 1.02, depth_shift_px: [2, -3],
      faults: ["1 frame late", "depth scale +1.0 %"] },
    { serial: "cam-5", time_offset_frames: -2, rotation_deg: 0.1, translation_mm: 1,
      image_shift_px: 0.2, residual_px_before: null, residual_px_after: null,
      depth_scale_percent: null, depth_shift_px: null, faults: [] },
  ],
};

test("rigRows writes every figure with its unit and names the faults", () => {
  const rows = rigRows(report);
  assert.deepEqual(rows.map((r) => r.faulty), [false, true, false]);
  assert.deepEqual(rows[1].cells, ["cam-3", "+1 frame", "0.46° 4.0 mm", "6.3 px",
    "9.10 → 2.60 px", "+1.02 %", "(2, -3) px", "1 frame late; depth scale +1.0 %"]);
  assert.equal(rows[0].cells[7], "ok");
  assert.equal(rows[2].cells[1], "-2 frames");
  assert.equal(rows[2].cells[4], "– → – px");
  assert.equal(rows[2].cells[5], "–");
});

test("rigSummary says which version, what is off and what is in use", () => {
  assert.equal(rigSummary({ report, version_in_use: 0 }),
    "Version 2 from 48 accepted assignments; cameras off: cam-3. (the imported calibration " +
    "is in use.)");
  assert.match(rigSummary({ report: { ...report, faulty: [] }, version_in_use: 2 }),
    /no camera is off\. \(version 2 is in use\.\)/);
  assert.equal(rigSummary({ report: null, job_status: "queued" }),
    "Estimating the rig from the accepted labels…");
  assert.equal(rigSummary({ report: null, job_status: null }), "No rig-health estimate yet.");
});

test("rigHandLines says how far the hand shape is off and what the version does about it", () => {
  const hands = [{ index: 0, side: "right", calib_name: "20200709_subject_01", frames: 24,
    bone_diff_median_mm: 2.04, bone_diff_max_mm: 5.42, fitted_betas: [],
    faults: ["hand shape off: its bones differ from the labelled ones by 2.0 mm"] }];
  const [line] = rigHandLines({ ...report, hands });
  assert.equal(line.faulty, true);
  assert.equal(line.text, "Hand 0 right (mano_20200709_subject_01): shape off. Its bones " +
    "differ from the labelled ones by 2.0 mm (median of 20 bones, at most 5.4 mm) over 24 " +
    "frames; this version uses the shape fitted to the labels.");
  const ok = rigHandLines({ ...report, hands: [{ ...hands[0], calib_name: null, faults: [] }] });
  assert.equal(ok[0].faulty, false);
  assert.match(ok[0].text, /^Hand 0 right: shape ok\. Its bones are within 2\.0 mm .* the labelled ones\.$/);
  assert.deepEqual(rigHandLines(report), []);
  assert.match(rigSummary({ report: { ...report, hands }, version_in_use: 0 }),
    /cameras off: cam-3\. The hand's shape is off\. \(the imported/);
});
