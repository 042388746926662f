// Submit checks: problems regrouped frame by frame, from the core completeness check.
import assert from "node:assert/strict";
import { test } from "node:test";

import { AnnotationStore } from "../../frontend/annotate/core/store.js";
import { checkWork, imageWarnings, problemsByFrame } from "../../frontend/annotate/core/checks.js";

test("runs of frames missing the same points become one line each", () => {
  const problems = [
    { point: 0, frames: [[0, 4]], message: "" },
    { point: 2, frames: [[3, 6], [9, 9]], message: "" },
  ];
  assert.deepEqual(problemsByFrame(problems, 10), [
    { from: 0, to: 2, points: [0] },
    { from: 3, to: 4, points: [0, 2] },
    { from: 5, to: 6, points: [2] },
    { from: 9, to: 9, points: [2] },
  ]);
});

test("complete work has no problems; an all-static track is flagged for a confirm", () => {
  const store = new AnnotationStore({ numPoints: 2, numFrames: 5, width: 64, height: 48 });
  const task = { num_frames: 5, point_names: ["a", "b"] };
  let check = checkWork(store, task);
  assert.equal(check.complete, false);
  assert.deepEqual(check.byFrame, [{ from: 0, to: 4, points: [0, 1] }]);
  store.placePoint(0, 0, 10, 10);
  store.placePoint(1, 0, 30, 30);
  store.toggleVisibility(1, 3);
  check = checkWork(store, task);
  assert.equal(check.complete, true);
  assert.deepEqual(check.warnings.map((w) => w.kind), ["static"]);
  store.placePoint(0, 4, 20, 12);
  assert.deepEqual(checkWork(store, task).warnings, []);
});

test("the server's image check becomes one warning per stretch, in its words", () => {
  const reply = { warnings: [{ point: 16, frames: [4, 8], frame: 6, offset_px: 14.2,
    message: "ring tip moves 14 px between frames 4 and 8 that the track does not follow" }] };
  assert.deepEqual(imageWarnings(reply), [{ kind: "stretch", point: 16, frame: 6,
    message: "ring tip moves 14 px between frames 4 and 8 that the track does not follow: " +
      "add a keyframe where it turns" }]);
  assert.deepEqual(imageWarnings(null), []);
  assert.deepEqual(imageWarnings({ warnings: [] }), []);
});
