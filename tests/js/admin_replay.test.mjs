import assert from "node:assert/strict";
import { test } from "node:test";

import {
  ERROR_MAX_PX, NO_ERROR, cellAt, errorColour, evidenceFeedback, followView, heatFontPx,
  heatLayout, pointAt, spanRows, spansOf, stepFrame, viewport, zoomAt,
} from "../../frontend/admin/core/replay.js";

const hue = (/** @type {string} */ colour) => Number(/hsl\((\d+)/.exec(colour)?.[1]);

test("error colours run from green at 0 px to red at the top of the scale", () => {
  assert.equal(hue(errorColour(0)), 120);
  assert.equal(hue(errorColour(ERROR_MAX_PX / 2)), 60);
  assert.equal(hue(errorColour(ERROR_MAX_PX)), 0);
  assert.equal(hue(errorColour(10 * ERROR_MAX_PX)), 0);
  assert.ok(hue(errorColour(3)) > hue(errorColour(12)));
  assert.equal(errorColour(null), NO_ERROR);
  assert.equal(errorColour(Number.NaN), NO_ERROR);
});

test("a hand's 21 heat map rows are tall enough for 13 px names", () => {
  const hand = heatLayout(72, 21, 900);
  assert.ok(hand.row >= 15, String(hand.row));
  assert.equal(heatFontPx(hand.row), 13);
  assert.equal(heatLayout(72, 2, 900).row, 22);
  assert.ok(heatFontPx(9) <= 9);
});

test("heat map cells are found back from where they are drawn", () => {
  const layout = heatLayout(16, 21, 92 + 16 * 20);
  assert.equal(layout.cell, 20);
  assert.deepEqual(cellAt(layout, 92 + 3 * 20 + 5, 4 * layout.row + 2, 16, 21),
    { frame: 3, point: 4 });
  assert.equal(cellAt(layout, 50, 10, 16, 21), null);
  assert.equal(cellAt(layout, 92 + 16 * 20 + 1, 10, 16, 21), null);
  assert.equal(cellAt(layout, 100, 21 * layout.row + 1, 16, 21), null);
});

test("swaps and issues become labelled spans, overlapping ones on separate rows", () => {
  const names = Array.from({ length: 21 }, (_, i) => `j${i}`);
  const spans = spansOf(
    [{ kind: "swap", fingers: ["ring", "little"], frames: [4, 10],
      message: "ring and little swapped in frames 4-10" }],
    [{ point: 20, frames: [5, 9], error_px: 12.4 }, { point: 3, frames: [12, 13] }], names);
  assert.deepEqual(spans.map((s) => s.kind), ["swap", "issue", "issue"]);
  assert.equal(spans[0].label, "swap ring ↔ little");
  assert.deepEqual(spans[0].points, [13, 14, 15, 16, 17, 18, 19, 20]);
  assert.equal(spans[0].detail, "ring and little swapped in frames 4-10");
  assert.equal(spans[1].label, "j20 12 px");
  assert.equal(spans[1].detail, "j20 off by 12 px in frames 5–9");
  assert.deepEqual(spanRows(spans), [0, 1, 0]);
});

test("a rejection's feedback starts from QC's and adds each span once", () => {
  const text = evidenceFeedback({
    feedback: "Several joints are far from where the other views place them.",
    swaps: [{ kind: "swap", fingers: ["ring", "little"], frames: [4, 10],
      message: "ring and little swapped in frames 4-10" }],
    issues: [{ point: 0, frames: [2, 2], error_px: 30 }, { point: 16, frames: [5, 8], error_px: 22 }],
    point_names: Array.from({ length: 21 }, (_, i) => (i ? `joint_${i}` : "wrist")),
  });
  assert.deepEqual(text.split("\n"), [
    "Several joints are far from where the other views place them.",
    "Ring and little swapped in frames 4-10.",
    "Wrist off by 30 px in frame 2.",
  ]);
  assert.equal(evidenceFeedback({ feedback: "x ring and little swapped in frames 4-10 y",
    swaps: [{ frames: [4, 10], fingers: ["ring", "little"],
      message: "ring and little swapped in frames 4-10" }] }).split("\n").length, 1);
  assert.equal(evidenceFeedback({}), "");
});

test("the viewport maps image pixels to the canvas and back, zooming about a point", () => {
  const image = { width: 640, height: 480 }, canvas = { width: 320, height: 240 };
  const whole = viewport(image, canvas, { zoom: 1, cx: 320, cy: 240 });
  assert.deepEqual(whole.toCanvas(0, 0), [0, 0]);
  assert.deepEqual(whole.toCanvas(640, 480), [320, 240]);
  const zoomed = zoomAt(image, canvas, { zoom: 1, cx: 320, cy: 240 }, 2, 80, 60);
  assert.equal(zoomed.zoom, 2);
  const vp = viewport(image, canvas, zoomed);
  const [x, y] = vp.toCanvas(160, 120);  // the image point under (80, 60) before
  assert.ok(Math.abs(x - 80) < 1e-9 && Math.abs(y - 60) < 1e-9);
  assert.deepEqual(vp.toImage(...vp.toCanvas(33, 44)).map((v) => Math.round(v)), [33, 44]);
  assert.deepEqual(zoomAt(image, canvas, zoomed, 0.1, 0, 0), { zoom: 1, cx: 320, cy: 240 });
});

test("frames step within the clip, and playing wraps around", () => {
  assert.equal(stepFrame(0, -1, 12), 0);
  assert.equal(stepFrame(11, 1, 12), 11);
  assert.equal(stepFrame(11, 1, 12, true), 0);
  assert.equal(stepFrame(5, 1, 12), 6);
});

test("a point's worker position, flag, reference and error are read per frame", () => {
  const review = {
    track: { xy: [[[10, 20], [null, null]]], visible: [[1, 0]] },
    reference: [[[12, 20], null]], errors: [[2.0, null]], reference_shown: null,
  };
  assert.deepEqual(pointAt(review, 0, 0),
    { xy: [10, 20], visible: true, reference: [12, 20], referenceShown: true, error: 2.0 });
  assert.deepEqual(pointAt(review, 0, 1),
    { xy: null, visible: false, reference: null, referenceShown: true, error: null });
  assert.equal(pointAt({ ...review, reference: null, errors: null }, 0, 0).reference, null);
});

test("the followed view zooms to the largest frame's points and centres on this frame's", () => {
  const image = { width: 640, height: 480 };
  const track = [
    [[100, 100], [140, 130]],  // a 40 x 30 box
    [[300, 200], [320, 210]],
    [null, [null, null]],  // no points: the nearest frame's centre
  ];
  const first = followView(image, [track], 0, 3, 0);
  assert.equal(first.zoom, 6);  // 640 / 40 = 16, held to 6
  assert.deepEqual([first.cx, first.cy], [120, 115]);
  const last = followView(image, [track], 2, 3, 0);
  assert.deepEqual([last.cx, last.cy], [310, 205]);
  const wide = followView(image, [[[[0, 0], [600, 400]]]], 0, 1, 0.5);
  assert.equal(wide.zoom, 1);
  assert.deepEqual(followView(image, [null], 0, 1), { zoom: 1, cx: 320, cy: 240 });
});

test("issues of points QC's feedback already names are not told twice", () => {
  const text = evidenceFeedback({
    feedback: "Check these frames: the landmark 1 jumped 14 px between frames 8 and 9.",
    issues: [{ point: 0, frames: [8, 9], error_px: 14, about: "jump" },
      { point: 1, frames: [3, 4], error_px: 20 }],
    point_names: ["landmark_1", "landmark_2"],
  });
  assert.deepEqual(text.split("\n"), [
    "Check these frames: the landmark 1 jumped 14 px between frames 8 and 9.",
    "Landmark 2 off by 20 px in frames 3–4.",
  ]);
});
