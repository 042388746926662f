import { test } from "node:test";
import assert from "node:assert/strict";

import { lastFrameKey, readLastFrame, writeLastFrame } from "../../frontend/annotate/core/lastframe.js";

/** A Storage stand-in over a Map. */
function memoryStorage() {
  const items = new Map();
  return {
    getItem: (k) => (items.has(k) ? items.get(k) : null),
    setItem: (k, v) => items.set(k, String(v)),
  };
}

test("the last frame is kept per assignment, a preview's per task", () => {
  assert.equal(lastFrameKey({ task: { id: 4 }, assignment: { id: 17 } }), "dexlabel:frame:a17");
  assert.equal(lastFrameKey({ task: { id: 4 }, assignment: null }), "dexlabel:frame:t4");
});

test("a written frame reads back; none kept reads as frame 0", () => {
  const store = memoryStorage();
  const storage = () => store;
  assert.equal(readLastFrame(storage, "k", 72), 0);
  writeLastFrame(storage, "k", 41);
  assert.equal(readLastFrame(storage, "k", 72), 41);
});

test("a kept frame outside the clip or not a number reads as frame 0", () => {
  const store = memoryStorage();
  const storage = () => store;
  for (const bad of ["72", "-3", "2.5", "frame", ""]) {
    store.setItem("k", bad);
    assert.equal(readLastFrame(storage, "k", 72), 0, bad);
  }
});

test("a storage that refuses (a sandboxed frame) reads 0 and writes nothing, silently", () => {
  const refused = () => { throw new Error("SecurityError"); };
  assert.equal(readLastFrame(refused, "k", 72), 0);
  assert.doesNotThrow(() => writeLastFrame(refused, "k", 5));
});
