import { test } from "node:test";
import assert from "node:assert/strict";

import { fittedHeight, taskFacts } from "../../frontend/market/views.js";

test("the task frame fills the window below its top edge", () => {
  assert.equal(fittedHeight(700, 64), 630);
  assert.equal(fittedHeight(768, 64.5), 697);
});

test("a short window still gets a workable frame", () => {
  assert.equal(fittedHeight(300, 64), 320);
});

test("a HIT row names its target, view and frame count", () => {
  assert.equal(taskFacts({ target: "right hand", view: "800007060125", frames: 72 }),
    "right hand · view 800007060125 · 72 frames");
  assert.equal(taskFacts(null), "");
});
