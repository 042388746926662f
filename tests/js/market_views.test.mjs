import { test } from "node:test";
import assert from "node:assert/strict";

import { fittedHeight, hitMarks, taskFacts } from "../../frontend/market/views.js";

test("the task frame fills the window below its top edge", () => {
  assert.equal(fittedHeight(700, 64), 630);
  assert.equal(fittedHeight(768, 64.5), 697);
});

test("a short window still gets a workable frame", () => {
  assert.equal(fittedHeight(300, 64), 320);
});

test("a HIT row names its target, view and frame count", () => {
  assert.equal(taskFacts({ target: "right hand", view: "800007060125",
    view_name: "camera 3 of 8", frames: 72 }), "right hand · camera 3 of 8 · 72 frames");
  assert.equal(taskFacts(null), "");
});

test("a team task assigned to the worker says so before their own assignment's mark", () => {
  assert.deepEqual(hitMarks({ assigned_to_me: true,
    mine: { assignment_id: "3AB", status: "Accepted" } }), [
    { text: "assigned to you", kind: "assigned" },
    { text: "accepted · continue", kind: "accepted", href: "#/work/3AB" },
  ]);
  assert.deepEqual(hitMarks({ assigned_to_me: false, mine: { assignment_id: "3AB",
    status: "Submitted" } }), [{ text: "submitted", kind: "submitted" }]);
  assert.deepEqual(hitMarks({ mine: null }), []);
});
