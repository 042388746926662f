// Interpolation, completeness and suspicious-work checks against the shared golden vectors.
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { describe, test } from "node:test";

import {
  completeness,
  denseTrack,
  formatSpans,
  frameSpans,
  suspicious,
  valueAt,
} from "../../frontend/annotate/core/interpolate.js";

const golden = JSON.parse(
  readFileSync(new URL("../fixtures/interpolation_golden.json", import.meta.url), "utf8"),
);

describe("denseTrack matches the golden vectors", () => {
  for (const c of golden.dense_cases) {
    test(c.name, () => {
      // Exact equality: both languages use the same formula in the same order.
      assert.deepEqual(denseTrack(c.keyframes, c.num_frames), c.dense);
    });
  }
});

describe("valueAt agrees with denseTrack", () => {
  for (const c of golden.dense_cases) {
    test(c.name, () => {
      c.dense.forEach((expected, f) => assert.deepEqual(valueAt(c.keyframes, f), expected));
    });
  }
});

describe("completeness matches the golden vectors", () => {
  for (const c of golden.completeness_cases) {
    test(c.name, () => {
      const result = completeness(c.tracks, c.num_frames, c.point_names);
      assert.deepEqual(result, { complete: c.complete, problems: c.problems });
    });
  }
});

describe("suspicious matches the golden vectors", () => {
  for (const c of golden.suspicious_cases) {
    test(c.name, () => {
      assert.deepEqual(suspicious(c.tracks, c.num_frames, c.point_names), c.warnings);
    });
  }
});

test("golden file covers the required cases", () => {
  const names = golden.dense_cases.map((c) => c.name);
  for (const required of [
    "empty", "single keyframe", "two keyframes linear", "occluded span in the middle",
    "occluded keyframe without position", "fractional coordinates",
    "frames after last keyframe", "frame 0 not a keyframe",
  ]) {
    assert.ok(names.includes(required), `missing golden case ${required}`);
  }
  assert.ok(golden.completeness_cases.length > 0);
});

test("frameSpans groups consecutive frames", () => {
  assert.deepEqual(frameSpans([true, true, false, true, false, false, true, true]),
    [[0, 1], [3, 3], [6, 7]]);
  assert.deepEqual(frameSpans([]), []);
});

test("formatSpans names a single frame in the singular", () => {
  assert.equal(formatSpans([[5, 5]]), "frame 5");
  assert.equal(formatSpans([[0, 11], [20, 20]]), "frames 0-11, 20");
  assert.equal(formatSpans([[3, 4]]), "frames 3-4");
});

test("completeness without point names falls back to indices", () => {
  const result = completeness([[], [{ frame: 0, x: 1, y: 1, visible: true }]], 3);
  assert.equal(result.complete, false);
  assert.deepEqual(result.problems,
    [{ point: 0, frames: [[0, 2]], message: "point 0: no keyframes" }]);
});

test("valueAt between keyframes does not mutate the keyframes", () => {
  const keyframes = [
    { frame: 0, x: 0, y: 0, visible: true },
    { frame: 2, x: 2, y: 4, visible: true },
  ];
  const copy = structuredClone(keyframes);
  valueAt(keyframes, 1);
  denseTrack(keyframes, 3)[0].x = 99;
  assert.deepEqual(keyframes, copy);
});
