// A tracking proposal's request, answer and held frames (annotate/core/proposals.js).
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  heldFrames, heldRuns, proposalRequest, proposalsFrom,
} from "../../frontend/annotate/core/proposals.js";

const kf = (frame, x, y, source = "placed", visible = true) => ({ frame, x, y, visible, source });

test("proposalRequest sends each point's anchors and the frames covering every span", () => {
  const keyframes = new Map([
    [0, [kf(2, 10, 10), kf(4, 12, 10, "tracked"), kf(8, 16, 10)]],
    [3, [kf(5, 1, 1), kf(12, 8, 1, "prefilled")]],
  ]);
  const body = proposalRequest(new Map([[0, [[2, 8]]], [3, [[5, 12]]]]), (p) => keyframes.get(p),
    20);
  assert.deepEqual(body, {
    tracks: [
      { point: 0, keyframes: [[2, 10, 10, 1], [8, 16, 10, 1]] },
      { point: 3, keyframes: [[5, 1, 1, 1], [12, 8, 1, 1]] },
    ],
    first_frame: 2,
    last_frame: 12,
  });
});

test("proposalsFrom keeps the points asked for, each with the spans it decides", () => {
  const answer = { first_frame: 2, last_frame: 8, points: [
    { point: 0, xy: [[1, 1]], ok: [true] },
    { point: 5, xy: [[2, 2]], ok: [false] },
  ] };
  assert.deepEqual(proposalsFrom(answer, new Map([[0, [[2, 8]]]])), [
    { point: 0, first: 2, last: 8, spans: [[2, 8]], xy: [[1, 1]], ok: [true] },
  ]);
});

test("heldFrames and heldRuns: inner span frames where the proposal holds, in runs", () => {
  const xy = [[0, 0], [1, 1], [2, 2], null, [4, 4], [5, 5], [6, 6]];
  const p = { point: 0, first: 10, last: 16, spans: [[10, 16]], xy,
    ok: [true, true, true, true, false, true, true] };
  // Frame 10 and 16 are the anchors; 13 has no position, 14 was lost.
  assert.deepEqual(heldFrames(p), [11, 12, 15]);
  assert.deepEqual(heldRuns(p), [[[1, 1], [2, 2]], [[5, 5]]]);
  assert.deepEqual(heldFrames({ ...p, spans: [] }), []);
});
