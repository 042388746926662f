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

/** A stored keyframe object. */
function kf(frame, x, y, visible, source = "placed") {
  return { frame, x, y, visible, source };
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
  assert.deepEqual(store.keyframeAt(3, 10), kf(10, 100.12, 50.99, true));
  store.placePoint(3, 10, 101, 51);
  assert.deepEqual(store.keyframes(3), [kf(10, 101, 51, true)]);
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
  assert.deepEqual(store.keyframeAt(0, 0), kf(0, 639.99, 0, true));
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
  assert.deepEqual(store.keyframeAt(0, 5), kf(5, 2, 2, true));
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
  assert.deepEqual(store.keyframeAt(0, 3), kf(3, 30, 15, false));
  // Visibility holds until the next keyframe.
  assert.equal(store.valueAt(0, 6).visible, false);
  assert.equal(store.valueAt(0, 10).visible, true);
});

test("toggleVisibility rounds an interpolated position onto the stored grid", () => {
  const store = newStore();
  store.placePoint(0, 0, 0, 0);
  store.placePoint(0, 3, 10, 10);
  store.toggleVisibility(0, 1);
  assert.deepEqual(store.keyframeAt(0, 1), kf(1, 3.33, 3.33, false));
});

test("toggleVisibility at a keyframe flips it in place", () => {
  const store = newStore();
  store.placePoint(0, 4, 7, 8);
  store.toggleVisibility(0, 4);
  assert.deepEqual(store.keyframes(0), [kf(4, 7, 8, false)]);
  store.toggleVisibility(0, 4);
  assert.deepEqual(store.keyframes(0), [kf(4, 7, 8, true)]);
});

test("toggleVisibility before the first keyframe marks the point occluded", () => {
  const store = newStore();
  assert.equal(store.toggleVisibility(5, 0), true);
  assert.deepEqual(store.keyframeAt(5, 0), kf(0, null, null, false));
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

// ---- provenance -------------------------------------------------------------------------------

/** A store with point 0 accepted from tracking at frames 0..4 and a placed keyframe at 10. */
function withTracked() {
  const store = newStore();
  const entries = [0, 1, 2, 3, 4].map((f) => ({ frame: f, x: 10 + f, y: 20, visible: true,
    source: "tracked" }));
  store.setKeyframes(0, entries);
  store.placePoint(0, 10, 50, 50);
  return store;
}

test("keyframes carry their source, placed when none is given", () => {
  const store = newStore();
  store.placePoint(0, 0, 1, 2);
  store.setKeyframe(1, 0, { x: 3, y: 4, visible: true, source: "prefilled" });
  store.placePoint(2, 0, 5, 6, { source: "tracked" });
  assert.deepEqual(store.keyframeAt(0, 0), kf(0, 1, 2, true, "placed"));
  assert.deepEqual(store.keyframeAt(1, 0), kf(0, 3, 4, true, "prefilled"));
  assert.deepEqual(store.keyframeAt(2, 0), kf(0, 5, 6, true, "tracked"));
  assert.ok(Object.isFrozen(store.keyframeAt(1, 0)));
});

test("moving a tracked or prefilled keyframe makes it edited; placed and edited stay", () => {
  const store = withTracked();
  store.setKeyframe(1, 3, { x: 1, y: 1, visible: true, source: "prefilled" });
  store.placePoint(0, 2, 30, 30);
  store.setKeyframe(1, 3, { x: 2, y: 2, visible: true });
  store.placePoint(0, 10, 51, 51);
  assert.equal(store.keyframeAt(0, 2).source, "edited");
  assert.equal(store.keyframeAt(1, 3).source, "edited");
  assert.equal(store.keyframeAt(0, 10).source, "placed");
  store.placePoint(0, 2, 31, 31);
  assert.equal(store.keyframeAt(0, 2).source, "edited");
  // Untouched neighbours keep their source.
  assert.equal(store.keyframeAt(0, 1).source, "tracked");
});

test("an explicit source wins over the edited rule", () => {
  const store = withTracked();
  store.setKeyframe(0, 1, { x: 40, y: 40, visible: true, source: "tracked" });
  assert.deepEqual(store.keyframeAt(0, 1), kf(1, 40, 40, true, "tracked"));
  store.placePoint(0, 10, 60, 60, { source: "prefilled" });
  assert.equal(store.keyframeAt(0, 10).source, "prefilled");
});

test("writing a suggestion's own value again is no edit and keeps its source", () => {
  const store = withTracked();
  const edits = store.editCount;
  assert.equal(store.placePoint(0, 3, 13, 20), false);
  assert.equal(store.keyframeAt(0, 3).source, "tracked");
  assert.equal(store.editCount, edits);
  // Re-labelling the same position with another explicit source is an edit.
  assert.equal(store.setKeyframe(0, 3, { x: 13, y: 20, visible: true, source: "placed" }), true);
  assert.equal(store.keyframeAt(0, 3).source, "placed");
});

test("toggling visibility of a suggestion makes it edited; a new toggle keyframe is placed", () => {
  const store = withTracked();
  store.setKeyframe(1, 0, { x: 5, y: 5, visible: true, source: "prefilled" });
  store.toggleVisibility(0, 2);
  store.toggleVisibility(1, 0);
  store.toggleVisibility(0, 7);
  assert.deepEqual(store.keyframeAt(0, 2), kf(2, 12, 20, false, "edited"));
  assert.deepEqual(store.keyframeAt(1, 0), kf(0, 5, 5, false, "edited"));
  assert.equal(store.keyframeAt(0, 7).source, "placed");
  store.undo();
  store.undo();
  assert.equal(store.keyframeAt(1, 0).source, "prefilled");
});

test("moving a keyframe in time keeps its source", () => {
  const store = withTracked();
  assert.equal(store.moveKeyframe(0, 4, 6), true);
  assert.deepEqual(store.keyframeAt(0, 6), kf(6, 14, 20, true, "tracked"));
});

test("setKeyframes writes a span as one undo step and one notification", () => {
  const store = newStore();
  store.placePoint(0, 0, 1, 1);
  store.placePoint(0, 30, 3, 3);
  store.placePoint(0, 40, 4, 4);
  const before = store.toJSON();
  const seen = [];
  store.subscribe((change) => seen.push(change));
  const entries = [];
  for (let f = 1; f < 30; f++) {
    entries.push({ frame: f, x: f, y: 2 * f, visible: true, source: "tracked" });
  }
  entries.push({ frame: 40, remove: true });
  entries.push({ frame: 50, remove: true }); // no keyframe there: nothing to do
  assert.equal(store.setKeyframes(0, entries), true);
  assert.equal(seen.length, 1);
  assert.deepEqual([seen[0].cause, seen[0].point, seen[0].points], ["edit", 0, [0]]);
  assert.deepEqual(seen[0].created, Array.from({ length: 29 }, (_, i) => i + 1));
  assert.deepEqual(seen[0].deleted, [40]);
  assert.deepEqual(store.keyframes(0).map((k) => k.frame),
    Array.from({ length: 31 }, (_, i) => i));
  assert.deepEqual(store.keyframeAt(0, 17), kf(17, 17, 34, true, "tracked"));
  const after = store.toJSON();
  assert.equal(store.undo(), true);
  assert.deepEqual(store.toJSON(), before);
  assert.equal(store.redo(), true);
  assert.deepEqual(store.toJSON(), after);
  assert.equal(seen.length, 3);
  assert.deepEqual(seen[1].deleted.length, 29);
});

test("setKeyframes validates every entry before writing any", () => {
  const store = newStore();
  const good = { frame: 1, x: 1, y: 1, visible: true };
  assert.throws(() => store.setKeyframes(0, [good, { ...good, frame: 1 }]),
    /frame 1: given twice/);
  assert.throws(() => store.setKeyframes(0, [good, { ...good, frame: 2, source: "guessed" }]),
    /point 0, frame 2: source must be one of placed, tracked, prefilled, edited, got "guessed"/);
  assert.throws(() => store.setKeyframes(0, [good, { ...good, frame: 72 }]), /frame must be/);
  assert.deepEqual(store.keyframes(0), []);
  assert.equal(store.editCount, 0);
  assert.equal(store.setKeyframes(0, []), false);
});

test("setKeyframes accepts a 2000-frame span quickly", () => {
  const store = newStore({ numFrames: 2000 });
  const entries = [];
  for (let f = 0; f < 2000; f++) {
    entries.push({ frame: f, x: f % 640, y: 1, visible: true, source: "tracked" });
  }
  const t0 = performance.now();
  store.setKeyframes(5, entries);
  const accept = performance.now() - t0;
  // Re-accepting over existing keyframes, and undo/redo, walk the same fast path.
  const shifted = entries.map((e) => ({ ...e, y: 2 }));
  const t1 = performance.now();
  store.setKeyframes(5, shifted);
  store.undo();
  store.redo();
  const rest = performance.now() - t1;
  assert.equal(store.keyframes(5).length, 2000);
  assert.equal(store.keyframeAt(5, 1999).y, 2);
  const took = `accept ${accept.toFixed(1)} ms, rest ${rest.toFixed(1)} ms`;
  assert.ok(accept < 200 && rest < 300, took);
});

test("setPose writes several points at one frame as one undo step", () => {
  const store = newStore();
  store.placePoint(0, 0, 10, 10);
  store.setKeyframe(1, 0, { x: 20, y: 20, visible: true, source: "prefilled" });
  store.placePoint(2, 5, 1, 1);
  const before = store.toJSON();
  const seen = [];
  store.subscribe((change) => seen.push(change));
  // Copy frame 0's pose to frame 5 and drop point 2's keyframe there.
  const pose = [0, 1].map((p) => ({ point: p, ...store.valueAt(p, 0) }));
  const entries = [...pose, { point: 2, remove: true }];
  assert.equal(store.setPose(5, entries, { label: "copy pose" }), true);
  assert.equal(seen.length, 1);
  assert.deepEqual([seen[0].label, seen[0].point, seen[0].points], ["copy pose", null, [0, 1, 2]]);
  assert.deepEqual([seen[0].created, seen[0].deleted], [[5], [5]]);
  assert.deepEqual(store.keyframeAt(0, 5), kf(5, 10, 10, true, "placed"));
  assert.deepEqual(store.keyframeAt(1, 5), kf(5, 20, 20, true, "placed"));
  assert.equal(store.keyframeAt(2, 5), null);
  store.undo();
  assert.deepEqual(store.toJSON(), before);
  assert.throws(() => store.setPose(5, [{ point: 0, x: 1, y: 1, visible: true },
    { point: 0, x: 2, y: 2, visible: true }]), /point 0, frame 5: given twice/);
});

test("a skeleton drag through setPose is one undo step; suggestions become edited", () => {
  const store = newStore();
  store.setPose(3, [0, 1, 2].map((p) => ({ point: p, x: 100 + p, y: 100, visible: true,
    source: "tracked" })));
  const before = store.toJSON();
  for (let step = 1; step <= 20; step++) {
    const moved = [0, 1, 2].map((p) => ({ point: p, x: 100 + p + step, y: 100 - step,
      visible: true }));
    store.setPose(3, moved, { gesture: "skeleton-1" });
  }
  assert.deepEqual(store.keyframeAt(2, 3), kf(3, 122, 80, true, "edited"));
  assert.equal(store.undo(), true);
  assert.deepEqual(store.toJSON(), before);
  assert.equal(store.keyframeAt(2, 3).source, "tracked");
});

test("toJSON writes the source only when not placed; fromJSON reads both row forms", () => {
  const store = withTracked();
  store.placePoint(0, 2, 30, 30);
  store.setKeyframe(1, 0, { x: null, y: null, visible: false, source: "prefilled" });
  const payload = JSON.parse(JSON.stringify(store.toJSON()));
  assert.deepEqual(payload.tracks[0].keyframes, [
    [0, 10, 20, 1, "tracked"], [1, 11, 20, 1, "tracked"], [2, 30, 30, 1, "edited"],
    [3, 13, 20, 1, "tracked"], [4, 14, 20, 1, "tracked"], [10, 50, 50, 1],
  ]);
  assert.deepEqual(payload.tracks[1].keyframes, [[0, null, null, 0, "prefilled"]]);
  const loaded = AnnotationStore.fromJSON(payload, TASK);
  assert.deepEqual(loaded.tracks(), store.tracks());
  assert.deepEqual(loaded.toJSON(), store.toJSON());
  // An explicit "placed" row is read and written back in the short form.
  const explicit = AnnotationStore.fromJSON({ version: 1, tracks: [{ point: 0,
    keyframes: [[0, 1, 1, 1, "placed"]] }] }, TASK);
  assert.deepEqual(explicit.toJSON().tracks[0].keyframes, [[0, 1, 1, 1]]);
});

test("fromJSON refuses an unknown source or a row of the wrong length, naming it", () => {
  const load = (keyframes) =>
    () => AnnotationStore.fromJSON({ version: 1, tracks: [{ point: 3, keyframes }] }, TASK);
  assert.throws(load([[12, 1, 1, 1, "guessed"]]),
    /point 3, frame 12: source must be one of placed, tracked, prefilled, edited, got "guessed"/);
  assert.throws(load([[12, 1, 1, 1, null]]), /got null/);
  assert.throws(load([[12, 1, 1, 1, "tracked", 0]]),
    /\[frame, x, y, visible01\] or \[frame, x, y, visible01, source\]/);
});

test("setTracks writes several points over several frames as one undo step", () => {
  const store = newStore();
  store.placePoint(0, 0, 10, 10);
  store.placePoint(0, 20, 30, 10);
  store.setKeyframe(3, 5, { x: 7, y: 7, visible: true, source: "prefilled" });
  store.placePoint(3, 9, 1, 2);
  store.placePoint(8, 4, 50, 60);
  const before = store.toJSON();
  const seen = [];
  store.subscribe((change) => seen.push(change));
  const tracked = (frames, x) =>
    frames.map((f) => ({ frame: f, x: x + f, y: 2 * f, visible: true, source: "tracked" }));
  const groups = [
    { point: 3, entries: [...tracked([5, 6, 7], 100), { frame: 9, remove: true }] },
    { point: 0, entries: tracked([1, 2, 19], 10) },
    { point: 8, entries: [{ frame: 4, x: 50, y: 60, visible: true }] }, // unchanged: skipped
    { point: 12, entries: [] },
  ];
  assert.equal(store.setTracks(groups, { label: "accept tracking" }), true);
  assert.equal(seen.length, 1);
  const change = seen[0];
  assert.deepEqual([change.cause, change.label, change.point, change.points],
    ["edit", "accept tracking", null, [0, 3]]);
  assert.deepEqual([change.created, change.updated, change.deleted],
    [[1, 2, 6, 7, 19], [5], [9]]);
  assert.deepEqual(store.keyframes(3).map((k) => [k.frame, k.x, k.source]),
    [[5, 105, "tracked"], [6, 106, "tracked"], [7, 107, "tracked"]]);
  assert.deepEqual(store.keyframes(0).map((k) => k.frame), [0, 1, 2, 19, 20]);
  const after = store.toJSON();
  assert.equal(store.undo(), true);
  assert.deepEqual(store.toJSON(), before, "one undo restores every point exactly");
  assert.deepEqual(store.keyframeAt(3, 5), kf(5, 7, 7, true, "prefilled"));
  assert.deepEqual([seen[1].cause, seen[1].points], ["undo", [0, 3]]);
  assert.deepEqual(seen[1].deleted, [1, 2, 6, 7, 19]);
  assert.equal(store.canUndo, true, "the edits before the batch are still there to undo");
  assert.equal(store.redo(), true);
  assert.deepEqual(store.toJSON(), after);
  assert.deepEqual([seen[2].cause, seen[2].points], ["redo", [0, 3]]);
  assert.equal(store.setTracks(groups), false, "the same batch again changes nothing");
});

test("setTracks validates every group and entry before writing any", () => {
  const store = newStore();
  const good = { point: 0, entries: [{ frame: 1, x: 1, y: 1, visible: true }] };
  const bad = (groups, pattern) => assert.throws(() => store.setTracks(groups), pattern);
  bad([good, { point: 0, entries: [] }], /point 0: given twice/);
  bad([good, { point: 21, entries: [] }], /point must be an integer in 0\.\.20, got 21/);
  bad([good, { point: 2, entries: {} }], /entriesByPoint\[1\] \(point 2\): entries must be/);
  bad([good, { point: 2, entries: [{ frame: 3, x: 1, y: 1, visible: true, source: "guess" }] }],
    /point 2, frame 3: source must be one of/);
  bad([good, { point: 2, entries: [{ frame: 3, x: 1, y: 1, visible: true },
    { frame: 3, remove: true }] }], /point 2, frame 3: given twice/);
  bad({ point: 0 }, /entriesByPoint must be an array/);
  assert.deepEqual(store.tracks().flat(), []);
  assert.equal(store.editCount, 0);
  assert.equal(store.setTracks([]), false);
});

test("setTracks writes 21 points x 2000 frames quickly, and undoes them as fast", () => {
  const numFrames = 2000;
  const store = newStore({ numFrames });
  const groups = Array.from({ length: 21 }, (_, point) => ({
    point, entries: Array.from({ length: numFrames }, (_, f) => ({
      frame: numFrames - 1 - f, x: (f + point) % 640, y: point, visible: true,
      source: "tracked" })),
  }));
  const t0 = performance.now();
  store.setTracks(groups);
  const write = performance.now() - t0;
  const t1 = performance.now();
  store.undo();
  store.redo();
  const rest = performance.now() - t1;
  assert.equal(store.keyframes(20).length, numFrames);
  assert.deepEqual(store.keyframes(20).slice(0, 2).map((k) => k.frame), [0, 1]);
  assert.equal(store.keyframeAt(20, 0).x, (numFrames - 1 + 20) % 640);
  const took = `write ${write.toFixed(1)} ms, undo + redo ${rest.toFixed(1)} ms`;
  assert.ok(write < 1000 && rest < 1000, took);
});

test("actionCount: a drag's steps are one action, undo and redo one each, no-ops none", () => {
  const store = newStore();
  store.placePoint(0, 0, 10, 10);
  for (let i = 1; i <= 5; i++) store.placePoint(0, 0, 10 + i, 10, { gesture: "drag-1" });
  assert.equal(store.actionCount, 2);
  store.placePoint(0, 0, 15, 10, { gesture: "drag-2" });
  assert.equal(store.actionCount, 2, "a step that changes nothing is no action");
  store.placePoint(0, 0, 20, 10, { gesture: "drag-2" });
  store.placePoint(0, 0, 25, 10, { gesture: "drag-2" });
  assert.equal(store.actionCount, 3);
  store.undo();
  store.redo();
  assert.equal(store.actionCount, 5);
  store.setTracks([{ point: 1, entries: [{ frame: 3, x: 1, y: 1, visible: true }] }],
    { automatic: true });
  assert.equal(store.actionCount, 5, "what the page writes by itself is no action");
  assert.ok(store.editCount > store.actionCount);
});
