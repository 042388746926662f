// The annotation store: edits, visibility toggling, change notifications, JSON round trip.
import assert from "node:assert/strict";
import { test } from "node:test";

import { AnnotationStore } from "../../frontend/annotate/core/store.js";

const TASK = { numPoints: 21, numFrames: 72, width: 640, height: 480 };

function newStore(overrides = {}) {
  return new AnnotationStore({ ...TASK, ...overrides });
}

/** Deterministic pseudo-random numbers in [0, 1) (a 32-bit LCG), so the tests are repeatable. */
function lcg(seed) {
  let state = seed >>> 0;
  return () => {
    state = (Math.imul(state, 1664525) + 1013904223) >>> 0;
    return state / 2 ** 32;
  };
}

function fullyKeyed(seed = 7) {
  const random = lcg(seed);
  const store = newStore();
  for (let p = 0; p < TASK.numPoints; p++) {
    for (let f = 0; f < TASK.numFrames; f++) {
      store.setKeyframe(p, f, {
        x: random() * TASK.width, y: random() * TASK.height, visible: random() > 0.2,
      });
    }
  }
  return store;
}

test("placePoint creates a visible keyframe and then updates it", () => {
  const store = newStore();
  assert.equal(store.placePoint(3, 10, 100.123, 50.987), true);
  assert.deepEqual(store.keyframeAt(3, 10), { frame: 10, x: 100.12, y: 50.99, visible: true });
  store.placePoint(3, 10, 101, 51);
  assert.deepEqual(store.keyframes(3), [{ frame: 10, x: 101, y: 51, visible: true }]);
  assert.equal(store.valueAt(3, 20).state, "interpolated");
  assert.equal(store.valueAt(3, 5).state, "unplaced");
});

test("keyframes stay sorted by frame whatever the editing order", () => {
  const store = newStore();
  for (const f of [40, 5, 71, 0, 20]) store.placePoint(0, f, f, f);
  assert.deepEqual(store.keyframes(0).map((k) => k.frame), [0, 5, 20, 40, 71]);
});

test("positions are clamped into the image", () => {
  const store = newStore();
  assert.deepEqual(store.clampToImage(-5, 1e6), { x: 0, y: 479.99 });
  assert.deepEqual(store.clampToImage(639.996, 12.345), { x: 639.99, y: 12.35 });
  store.placePoint(0, 0, 700, -1);
  assert.deepEqual(store.keyframeAt(0, 0), { frame: 0, x: 639.99, y: 0, visible: true });
});

test("setting an identical keyframe is not an edit", () => {
  const store = newStore();
  store.placePoint(1, 2, 10, 20);
  assert.equal(store.placePoint(1, 2, 10, 20), false);
  assert.equal(store.editCount, 1);
});

test("invalid input is refused with a clear error", () => {
  const store = newStore();
  assert.throws(() => store.placePoint(21, 0, 1, 1), /point must be an integer in 0..20/);
  assert.throws(() => store.placePoint(0, 72, 1, 1), /frame must be an integer in 0..71/);
  assert.throws(() => store.placePoint(0, 1.5, 1, 1), /frame must be an integer/);
  assert.throws(() => store.placePoint(0, 0, NaN, 1), /finite numbers/);
  const visibleNowhere = { x: null, y: null, visible: true };
  assert.throws(() => store.setKeyframe(0, 0, visibleNowhere), /needs a position/);
  assert.equal(store.editCount, 0);
});

test("moveKeyframe moves in time and never overwrites another keyframe", () => {
  const store = newStore();
  store.placePoint(0, 0, 1, 1);
  store.placePoint(0, 10, 2, 2);
  assert.equal(store.moveKeyframe(0, 10, 5), true);
  assert.deepEqual(store.keyframes(0).map((k) => k.frame), [0, 5]);
  assert.deepEqual(store.keyframeAt(0, 5), { frame: 5, x: 2, y: 2, visible: true });
  assert.equal(store.moveKeyframe(0, 5, 0), false);
  assert.equal(store.moveKeyframe(0, 30, 31), false);
  assert.deepEqual(store.keyframes(0).map((k) => k.frame), [0, 5]);
});

test("deleteKeyframe removes only an existing keyframe", () => {
  const store = newStore();
  store.placePoint(2, 4, 1, 1);
  assert.equal(store.deleteKeyframe(2, 5), false);
  assert.equal(store.deleteKeyframe(2, 4), true);
  assert.deepEqual(store.keyframes(2), []);
});

test("toggleVisibility between keyframes keys the interpolated position, flipped", () => {
  const store = newStore();
  store.placePoint(0, 0, 0, 0);
  store.placePoint(0, 10, 100, 50);
  assert.equal(store.toggleVisibility(0, 3), true);
  assert.deepEqual(store.keyframeAt(0, 3), { frame: 3, x: 30, y: 15, visible: false });
  // Visibility holds until the next keyframe.
  assert.equal(store.valueAt(0, 6).visible, false);
  assert.equal(store.valueAt(0, 10).visible, true);
});

test("toggleVisibility rounds an interpolated position onto the stored grid", () => {
  const store = newStore();
  store.placePoint(0, 0, 0, 0);
  store.placePoint(0, 3, 10, 10);
  store.toggleVisibility(0, 1);
  assert.deepEqual(store.keyframeAt(0, 1), { frame: 1, x: 3.33, y: 3.33, visible: false });
});

test("toggleVisibility at a keyframe flips it in place", () => {
  const store = newStore();
  store.placePoint(0, 4, 7, 8);
  store.toggleVisibility(0, 4);
  assert.deepEqual(store.keyframes(0), [{ frame: 4, x: 7, y: 8, visible: false }]);
  store.toggleVisibility(0, 4);
  assert.deepEqual(store.keyframes(0), [{ frame: 4, x: 7, y: 8, visible: true }]);
});

test("toggleVisibility before the first keyframe marks the point occluded", () => {
  const store = newStore();
  assert.equal(store.toggleVisibility(5, 0), true);
  assert.deepEqual(store.keyframeAt(5, 0), { frame: 0, x: null, y: null, visible: false });
  // Turning a point without a position visible needs a placement, not a toggle.
  assert.equal(store.toggleVisibility(5, 0), false);
  assert.equal(store.toggleVisibility(5, 3), false);
});

test("subscribers get a change description for edits, undo, redo and saves", () => {
  const store = newStore();
  const seen = [];
  const unsubscribe = store.subscribe((change) => seen.push(change));
  store.placePoint(1, 3, 5, 5);
  store.placePoint(1, 3, 6, 6);
  store.moveKeyframe(1, 3, 4);
  store.undo();
  store.markSaved(9);
  unsubscribe();
  store.redo();
  const summary = seen.map((c) => [c.cause, c.point, c.created, c.updated, c.deleted, c.editCount]);
  assert.deepEqual(summary, [
    ["edit", 1, [3], [], [], 1],
    ["edit", 1, [], [3], [], 2],
    ["edit", 1, [4], [], [3], 3],
    ["undo", 1, [3], [], [4], 4],
    ["saved", null, [], [], [], 4],
  ]);
  assert.equal(store.version, 9);
  assert.equal(store.dirty, true);
});

test("markSaved with the edit count at send time keeps later edits dirty", () => {
  const store = newStore();
  store.placePoint(0, 0, 1, 1);
  const sentAt = store.editCount;
  store.placePoint(0, 1, 2, 2);
  store.markSaved(1, sentAt);
  assert.equal(store.dirty, true);
  store.markSaved(2);
  assert.equal(store.dirty, false);
});

test("toJSON and fromJSON round-trip exactly", () => {
  const store = fullyKeyed();
  store.toggleVisibility(3, 5);
  store.setKeyframe(4, 6, { x: null, y: null, visible: false });
  store.markSaved(12);
  const payload = JSON.parse(JSON.stringify(store.toJSON()));
  const loaded = AnnotationStore.fromJSON(payload, TASK);
  assert.deepEqual(loaded.tracks(), store.tracks());
  assert.deepEqual(loaded.toJSON(), store.toJSON());
  assert.equal(loaded.version, 12);
  assert.equal(loaded.canUndo, false);
});

test("payload uses compact rows", () => {
  const store = newStore({ numPoints: 2 });
  store.placePoint(0, 3, 1.5, 2.25);
  store.setKeyframe(1, 0, { x: null, y: null, visible: false });
  assert.deepEqual(store.toJSON(), {
    version: 0,
    tracks: [
      { point: 0, keyframes: [[3, 1.5, 2.25, 1]] },
      { point: 1, keyframes: [[0, null, null, 0]] },
    ],
  });
});

test("autosave payload of a fully keyed 21 x 72 task stays under 50 KB", (t) => {
  const bytes = Buffer.byteLength(JSON.stringify(fullyKeyed().toJSON()), "utf8");
  t.diagnostic(`payload bytes for 21 points x 72 frames, all keyed: ${bytes}`);
  assert.ok(bytes < 50 * 1024, `payload is ${bytes} bytes`);
});

test("fromJSON refuses malformed payloads with the field named", () => {
  assert.throws(() => AnnotationStore.fromJSON({ version: 1 }, TASK), /payload.tracks/);
  const load = (keyframes, point = 0) =>
    () => AnnotationStore.fromJSON({ version: 1, tracks: [{ point, keyframes }] }, TASK);
  assert.throws(load([[0, 1, 1]]), /\[frame, x, y, visible01\]/);
  assert.throws(load([[99, 1, 1, 1]]), /frame must be/);
  assert.throws(load([[0, 1, 1, 2]]), /visible must be 0 or 1/);
  assert.throws(load([[0, 1, 1, 1], [0, 2, 2, 1]]), /two keyframes/);
  assert.throws(load([], 21), /point must be/);
});
