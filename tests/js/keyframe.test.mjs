// One stored keyframe (core/keyframe.js) and what an edit changes (core/changes.js), apart from
// the store that uses them.
import assert from "node:assert/strict";
import { test } from "node:test";

import { applyWrites, changesFor } from "../../frontend/annotate/core/changes.js";
import {
  checkIndex, clampToImage, keyframeToRow, makeKeyframe, trackFromRows,
} from "../../frontend/annotate/core/keyframe.js";

const CLIP = { numFrames: 10, width: 640, height: 480 };

/** A stored keyframe object. */
function kf(frame, x, y, visible, source = "placed") {
  return { frame, x, y, visible, source };
}

test("checkIndex names the index, its range and the bad value", () => {
  checkIndex("frame", 9, 10);
  assert.throws(() => checkIndex("frame", 10, 10), /frame must be an integer in 0\.\.9, got 10/);
  assert.throws(() => checkIndex("point", 1.5, 21), /point must be an integer in 0\.\.20/);
});

test("clampToImage keeps a position inside the image on the 0.01 px grid", () => {
  assert.deepEqual(clampToImage(-5, 1e6, CLIP), { x: 0, y: 479.99 });
  assert.deepEqual(clampToImage(12.345, 639.996, { width: 20, height: 640 }), { x: 12.35, y: 639.99 });
});

test("makeKeyframe freezes a rounded keyframe and refuses a visible one without a position", () => {
  const k = makeKeyframe(3, { x: 1.006, y: 700, visible: true }, "tracked", CLIP);
  assert.deepEqual(k, kf(3, 1.01, 479.99, true, "tracked"));
  assert.ok(Object.isFrozen(k));
  assert.deepEqual(makeKeyframe(2, { x: null, y: null, visible: false }, "placed", CLIP),
    kf(2, null, null, false));
  assert.throws(() => makeKeyframe(2, { x: null, y: null, visible: true }, "placed", CLIP),
    /frame 2: a visible keyframe needs a position/);
  assert.throws(() => makeKeyframe(2, { x: 1, y: null, visible: false }, "placed", CLIP),
    /finite numbers or both null/);
  assert.throws(() => makeKeyframe(2, { x: 1, y: 1, visible: 1 }, "placed", CLIP),
    /visible must be a boolean/);
});

test("a track written as rows reads back as the same keyframes, sorted by frame", () => {
  const track = [kf(1, 10, 20, true), kf(4, null, null, false, "edited")];
  const rows = track.map(keyframeToRow);
  assert.deepEqual(rows, [[1, 10, 20, 1], [4, null, null, 0, "edited"]]);
  assert.deepEqual(trackFromRows(0, [rows[1], rows[0]], CLIP), track);
});

test("trackFromRows says which point and frame a bad row is at", () => {
  assert.throws(() => trackFromRows(2, "x", CLIP), /point 2: keyframes must be an array/);
  assert.throws(() => trackFromRows(2, [[1, 2, 3]], CLIP), /point 2: keyframe must be/);
  assert.throws(() => trackFromRows(2, [[1, 2, 3, 2]], CLIP), /point 2, frame 1: visible must/);
  assert.throws(() => trackFromRows(2, [[1, 2, 3, 1, "guessed"]], CLIP), /source must be one/);
  assert.throws(() => trackFromRows(2, [[1, 2, 3, 1], [1, 4, 5, 1]], CLIP),
    /point 2: two keyframes at frame 1/);
});

test("changesFor skips entries that change nothing and makes an edited suggestion 'edited'", () => {
  const tracks = [[kf(0, 5, 5, true, "tracked")], []];
  const same = changesFor(tracks, [{ point: 0, frame: null, entries: [
    { frame: 0, x: 5, y: 5, visible: true }] }], CLIP);
  assert.deepEqual(same, []);
  const changes = changesFor(tracks, [{ point: null, frame: 0, entries: [
    { point: 0, x: 6, y: 5, visible: true }, { point: 1, x: 1, y: 1, visible: true }] }], CLIP);
  assert.deepEqual(changes, [
    { point: 0, frame: 0, before: tracks[0][0], after: kf(0, 6, 5, true, "edited") },
    { point: 1, frame: 0, before: null, after: kf(0, 1, 1, true) },
  ]);
  assert.deepEqual(tracks, [[kf(0, 5, 5, true, "tracked")], []], "the tracks are only read");
});

test("changesFor refuses a cell given twice before anything is written", () => {
  const groups = [{ point: 0, frame: null, entries: [{ frame: 3, x: 1, y: 1, visible: true }] },
    { point: null, frame: 3, entries: [{ point: 0, remove: true }] }];
  assert.throws(() => changesFor([[]], groups, CLIP), /point 0, frame 3: given twice/);
});

test("applyWrites writes the tracks and describes what was created, updated and deleted", () => {
  const tracks = [[kf(0, 1, 1, true), kf(5, 2, 2, true)], [kf(2, 3, 3, true)]];
  const change = applyWrites(tracks, "set pose", [
    [0, 0, tracks[0][0], null], [0, 3, null, kf(3, 4, 4, true)],
    [1, 2, tracks[1][0], kf(2, 6, 6, true)]]);
  assert.deepEqual(change, { label: "set pose", point: null, points: [0, 1],
    created: [3], updated: [2], deleted: [0] });
  assert.deepEqual(tracks, [[kf(3, 4, 4, true), kf(5, 2, 2, true)], [kf(2, 6, 6, true)]]);
  assert.equal(applyWrites(tracks, "delete", [[1, 2, tracks[1][0], null]]).point, 1);
});
