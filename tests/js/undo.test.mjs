// The undo stack on its own, and every store edit undone and redone.
import assert from "node:assert/strict";
import { test } from "node:test";

import { AnnotationStore } from "../../frontend/annotate/core/store.js";
import { UndoStack } from "../../frontend/annotate/core/undo.js";

/** A command that appends to / removes from a log, for testing the stack alone. */
function pushCommand(log, value) {
  return {
    apply: () => { log.push(value); return `+${value}`; },
    revert: () => { log.pop(); return `-${value}`; },
  };
}

test("undo and redo walk the history in order", () => {
  const log = [];
  const stack = new UndoStack();
  assert.equal(stack.canUndo, false);
  stack.execute(pushCommand(log, 1));
  stack.execute(pushCommand(log, 2));
  assert.equal(stack.undo(), "-2");
  assert.deepEqual(log, [1]);
  assert.equal(stack.canRedo, true);
  assert.equal(stack.redo(), "+2");
  assert.deepEqual(log, [1, 2]);
  assert.equal(stack.redo(), undefined);
});

test("a new edit clears the redo history", () => {
  const log = [];
  const stack = new UndoStack();
  stack.execute(pushCommand(log, 1));
  stack.undo();
  stack.execute(pushCommand(log, 2));
  assert.equal(stack.canRedo, false);
  assert.deepEqual(log, [2]);
});

test("history is capped at the max depth, dropping the oldest steps", () => {
  const log = [];
  const stack = new UndoStack(3);
  for (let i = 0; i < 5; i++) stack.execute(pushCommand(log, i));
  assert.equal(stack.depth, 3);
  while (stack.canUndo) stack.undo();
  assert.deepEqual(log, [0, 1]);
  assert.throws(() => new UndoStack(0), /maxDepth/);
});

test("clear forgets undo and redo", () => {
  const stack = new UndoStack();
  stack.execute(pushCommand([], 1));
  stack.execute(pushCommand([], 2));
  stack.undo();
  stack.clear();
  assert.equal(stack.canUndo, false);
  assert.equal(stack.canRedo, false);
  assert.equal(stack.undo(), undefined);
});

const TASK = { numPoints: 3, numFrames: 20, width: 640, height: 480 };

/** Each edit, applied to a store that already holds some keyframes. */
const EDITS = {
  "placePoint new": (s) => s.placePoint(0, 7, 12.5, 13.5),
  "placePoint update": (s) => s.placePoint(0, 0, 99, 98),
  "setKeyframe occluded": (s) => s.setKeyframe(1, 3, { x: null, y: null, visible: false }),
  "moveKeyframe": (s) => s.moveKeyframe(0, 10, 15),
  "deleteKeyframe": (s) => s.deleteKeyframe(0, 10),
  "toggleVisibility between keyframes": (s) => s.toggleVisibility(0, 4),
  "toggleVisibility at keyframe": (s) => s.toggleVisibility(0, 0),
  "toggleVisibility unplaced": (s) => s.toggleVisibility(2, 0),
};

function seeded() {
  const store = new AnnotationStore(TASK);
  store.placePoint(0, 0, 10, 10);
  store.placePoint(0, 10, 20, 30);
  store.placePoint(1, 5, 300, 200);
  return store;
}

for (const [name, edit] of Object.entries(EDITS)) {
  test(`${name} is undoable and redoable`, () => {
    const store = seeded();
    const before = store.toJSON();
    assert.equal(edit(store), true);
    const after = store.toJSON();
    assert.notDeepEqual(after, before);
    assert.equal(store.undo(), true);
    assert.deepEqual(store.toJSON(), before);
    assert.equal(store.redo(), true);
    assert.deepEqual(store.toJSON(), after);
  });
}

test("a long random edit session undoes step by step to the start and redoes to the end", () => {
  const store = seeded();
  const states = [store.toJSON()];
  const ops = Object.values(EDITS);
  let seed = 12345;
  for (let i = 0; i < 60; i++) {
    seed = (seed * 1103515245 + 12345) % 2 ** 31;
    const point = seed % 3;
    const frame = (seed >> 4) % 20;
    const kind = (seed >> 9) % 4;
    let changed;
    if (kind === 0) changed = store.placePoint(point, frame, (seed >> 3) % 640, (seed >> 5) % 480);
    else if (kind === 1) changed = store.toggleVisibility(point, frame);
    else if (kind === 2) changed = store.deleteKeyframe(point, frame);
    else changed = ops[seed % ops.length](store);
    if (changed) states.push(store.toJSON());
  }
  assert.ok(states.length > 30, `only ${states.length - 1} edits changed anything`);
  for (let i = states.length - 2; i >= 0; i--) {
    assert.equal(store.undo(), true);
    assert.deepEqual(store.toJSON(), states[i]);
  }
  for (let i = 1; i < states.length; i++) {
    assert.equal(store.redo(), true);
    assert.deepEqual(store.toJSON(), states[i]);
  }
  assert.equal(store.canRedo, false);
});

test("edits of one drag gesture merge into a single undo step", () => {
  const store = seeded();
  const before = store.toJSON();
  for (let i = 0; i < 10; i++) store.placePoint(2, 8, 100 + i, 100, { gesture: "drag-1" });
  store.placePoint(2, 8, 200, 200, { gesture: "drag-2" });
  assert.deepEqual(store.keyframeAt(2, 8),
    { frame: 8, x: 200, y: 200, visible: true, source: "placed" });
  store.undo();
  assert.deepEqual(store.keyframeAt(2, 8),
    { frame: 8, x: 109, y: 100, visible: true, source: "placed" });
  store.undo();
  assert.deepEqual(store.toJSON(), before);
});
