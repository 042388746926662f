// Editing tools' pure logic: finger chains, copy pose, joint keys, typed frames, object outline.
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  chainFrom, copySummary, jointKeys, offObjectLandmarks, onOutline, outlineOf, parseFrame,
  pointForKey, previousPose,
} from "../../frontend/annotate/core/tools.js";

// The DexYCB/MANO 21-joint tree as the server sends it: [parent, child], fingers of 4 joints.
const PARENTS = [-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19];
const SKELETON = PARENTS.flatMap((parent, child) => (parent >= 0 ? [[parent, child]] : []));

test("a finger chain is the joint and the joints after it toward the tip", () => {
  assert.deepEqual(chainFrom(SKELETON, 5), [5, 6, 7, 8]);
  assert.deepEqual(chainFrom(SKELETON, 6), [6, 7, 8]);
  assert.deepEqual(chainFrom(SKELETON, 8), [8]);
  assert.deepEqual(chainFrom(SKELETON, 1), [1, 2, 3, 4]);
  assert.deepEqual(chainFrom(SKELETON, 19), [19, 20]);
});

test("the wrist and points without bones move alone in a chain drag", () => {
  assert.deepEqual(chainFrom(SKELETON, 0), [0]);
  assert.deepEqual(chainFrom([], 1), [1]);
});

test("previous pose takes each point's nearest keyframe strictly before the frame", () => {
  const tracks = [
    [{ frame: 0, x: 1, y: 2, visible: true }, { frame: 8, x: 3, y: 4, visible: true },
      { frame: 10, x: 9, y: 9, visible: true }],
    [{ frame: 5, x: 7, y: 8, visible: false }],
    [{ frame: 10, x: 5, y: 5, visible: true }],
    [],
  ];
  const got = previousPose(tracks, 10);
  assert.deepEqual(got, [
    { point: 0, from: 8, x: 3, y: 4, visible: true },
    { point: 1, from: 5, x: 7, y: 8, visible: false },
  ]);
  assert.equal(copySummary(got, 10), "copied 2 points from frames 5-8");
  assert.deepEqual(previousPose(tracks, 10, (p) => p === 0).map((c) => c.point), [1]);
  assert.equal(copySummary(previousPose(tracks, 6, (p) => p === 1), 6),
    "copied 1 point from frame 0");
  assert.equal(copySummary([], 0), "nothing to copy: no keyframe before frame 0");
});

test("hand joint keys: 1-9, 0 for 10, Shift adds 10, W for the wrist", () => {
  const keys = jointKeys("hand", 21);
  assert.equal(keys[0], "W");
  assert.equal(keys[1], "1");
  assert.equal(keys[10], "0");
  assert.equal(keys[11], "Shift+1");
  assert.equal(keys[20], "Shift+0");
  const press = (code, shiftKey = false, key = "") => pointForKey("hand", 21, { code, key, shiftKey });
  assert.equal(press("Digit1"), 1);
  assert.equal(press("Digit0"), 10);
  assert.equal(press("Numpad7"), 7);
  assert.equal(press("Digit3", true, "#"), 13);
  assert.equal(press("Digit0", true, ")"), 20);
  assert.equal(press("KeyW", false, "w"), 0);
  assert.equal(press("KeyQ", false, "q"), null);
  // Every joint has exactly one key, and each key picks its joint back.
  keys.forEach((k, p) => {
    const shift = k.startsWith("Shift+");
    const d = shift ? k.slice(6) : k;
    const e = d === "W" ? { code: "KeyW", key: "w", shiftKey: false }
      : { code: `Digit${d}`, key: d, shiftKey: shift };
    assert.equal(pointForKey("hand", 21, e), p, k);
  });
});

test("object landmarks are picked with 1 and 2; other keys pick nothing", () => {
  assert.deepEqual(jointKeys("object", 2), ["1", "2"]);
  const press = (code, shiftKey = false) => pointForKey("object", 2, { code, key: "", shiftKey });
  assert.equal(press("Digit1"), 0);
  assert.equal(press("Digit2"), 1);
  assert.equal(press("Digit3"), null);
  assert.equal(press("Digit0"), null);
  assert.equal(press("Digit1", true), null);
});

test("a typed frame is accepted in range and refused with the clip's range otherwise", () => {
  assert.deepEqual(parseFrame(" 7 ", 12), { frame: 7, error: null });
  assert.deepEqual(parseFrame("0", 12), { frame: 0, error: null });
  assert.equal(parseFrame("9999", 12).error, "frame 9999 is not in this clip (frames are 0-11)");
  assert.equal(parseFrame("12", 12).frame, null);
  assert.equal(parseFrame("-1", 12).error, '"-1" is not a frame number (frames are 0-11)');
  assert.equal(parseFrame("3.5", 12).frame, null);
  assert.equal(parseFrame("", 12).frame, null);
});

test("the outline comes from a polygon or a box", () => {
  assert.deepEqual(outlineOf({ box: [10, 20, 30, 40] }), [[10, 20], [30, 20], [30, 40], [10, 40]]);
  const tri = [[0, 0], [10, 0], [0, 10]];
  assert.equal(outlineOf({ polygon: tri }), tri);
  assert.equal(outlineOf(null), null);
  assert.equal(outlineOf({ polygon: [[0, 0], [1, 1]] }), null);
});

test("on the outline: inside, or within the tolerance of an edge", () => {
  const square = [[10, 10], [50, 10], [50, 50], [10, 50]];
  assert.ok(onOutline(square, 30, 30));
  assert.ok(onOutline(square, 10.5, 49.5));
  assert.ok(!onOutline(square, 60, 30));
  assert.ok(!onOutline(square, 52, 30));
  assert.ok(onOutline(square, 52, 30, 3));
  assert.ok(!onOutline(square, 54, 54, 3)); // 5.7 px from the corner
  // A concave outline: the notch is outside.
  const u = [[0, 0], [30, 0], [30, 30], [20, 30], [20, 10], [10, 10], [10, 30], [0, 30]];
  assert.ok(!onOutline(u, 15, 25));
  assert.ok(onOutline(u, 5, 25));
});

test("off-object landmarks: visible keyframes at the outline's frame outside it", () => {
  const square = [[10, 10], [50, 10], [50, 50], [10, 50]];
  const tracks = [
    [{ frame: 0, x: 80, y: 80, visible: true }, { frame: 3, x: 90, y: 90, visible: true }],
    [{ frame: 0, x: 20, y: 20, visible: true }],
    [{ frame: 0, x: 90, y: 90, visible: false }, { frame: 1, x: null, y: null, visible: false }],
  ];
  assert.deepEqual(offObjectLandmarks(tracks, square, 0, 3), [{ point: 0, frame: 0 }]);
  assert.deepEqual(offObjectLandmarks(tracks, square, 3, 3), [{ point: 0, frame: 3 }]);
});
