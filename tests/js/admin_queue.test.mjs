// The review queue's DOM-free part (admin/core/queue-core.js): row texts, the tally, where the
// queue moves, what a decision needs first and says after, and the keyboard.
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  bonusPaidText, decidedText, decisionProblem, itemToOpen, movedTo, nextAfterDecision,
  queueKeyAction, queueRowText, queueTally, rejectQuestion,
} from "../../frontend/admin/core/queue-core.js";

const ITEMS = [3, 6, 4].map((id) => ({ assignment_id: id }));

test("a listed report shows its error, what it is and its swaps and issues", () => {
  const item = { assignment_id: 3, error_px: 3.44, target_key: "hand:0", worker_id: "W1",
    sequence: "s/seq", swaps: 1, issues: 5 };
  assert.deepEqual(queueRowText(item), { error: "3.4 px", what: "#3 hand:0 · W1",
    where: "s/seq · 1 swap · 5 issues" });
  assert.deepEqual(queueRowText({ ...item, error_px: null, swaps: 2, issues: 0 }),
    { error: "–", what: "#3 hand:0 · W1", where: "s/seq · 2 swaps" });
});

test("the tally says when only the worst reports are listed", () => {
  assert.equal(queueTally(4, 4), "4 waiting for an admin");
  assert.equal(queueTally(250, 200), "250 waiting for an admin (the worst 200 listed)");
});

test("the queue opens the report asked for, else the first, else none", () => {
  assert.equal(itemToOpen(ITEMS, 4), ITEMS[2]);
  assert.equal(itemToOpen(ITEMS, 99), ITEMS[0]);
  assert.equal(itemToOpen(ITEMS, null), ITEMS[0]);
  assert.equal(itemToOpen([], 4), null);
});

test("next and previous stop at the ends of the list", () => {
  assert.equal(movedTo(ITEMS, 3, 1), 6);
  assert.equal(movedTo(ITEMS, 6, -1), 3);
  assert.equal(movedTo(ITEMS, 3, -1), null);
  assert.equal(movedTo(ITEMS, 4, 1), null);
  assert.equal(movedTo([], null, 1), null);
});

test("after a decision the next report opens, or the one before at the end", () => {
  assert.equal(nextAfterDecision(ITEMS, 3), 6);
  assert.equal(nextAfterDecision(ITEMS, 4), 6);
  assert.equal(nextAfterDecision([{ assignment_id: 3 }], 3), null);
});

test("a rejection needs feedback and a bonus a positive amount", () => {
  assert.match(decisionProblem("reject", "", "0.10"), /rejection needs feedback/);
  assert.equal(decisionProblem("reject", "wrong fingers", ""), null);
  assert.equal(decisionProblem("approve", "", ""), null);
  for (const amount of ["", "0", "-1", "ten"]) {
    assert.match(decisionProblem("bonus", "", amount), /bonus needs an amount/, amount);
  }
  assert.equal(decisionProblem("bonus", "", "0.10"), null);
});

test("a decision says what was done, and when it had been done before", () => {
  assert.equal(bonusPaidText({ amount: "0.10", worker_id: "W1" }, 3),
    "Bonus of $0.10 paid to W1 for assignment 3.");
  assert.equal(bonusPaidText({ amount: "0.10", worker_id: "W1", already_done: true }, 3),
    "Bonus of $0.10 paid to W1 for assignment 3 (already paid).");
  assert.equal(decidedText("approve", 3, {}), "Approved assignment 3.");
  assert.equal(decidedText("reject", 3, { already_done: true }),
    "Rejected assignment 3 (already done).");
});

test("keys map to queue actions in either case; others do nothing", () => {
  assert.equal(queueKeyAction("a"), "approve");
  assert.equal(queueKeyAction("R"), "reject");
  assert.equal(queueKeyAction("b"), "bonus");
  assert.equal(queueKeyAction("J"), "next");
  assert.equal(queueKeyAction("n"), "next");
  assert.equal(queueKeyAction("k"), "previous");
  assert.equal(queueKeyAction(" "), "play");
  assert.equal(queueKeyAction("ArrowLeft"), "back");
  assert.equal(queueKeyAction("ArrowRight"), "forward");
  for (const key of ["x", "Enter", "arrowleft", "toString", "Escape"]) {
    assert.equal(queueKeyAction(key), null, key);
  }
});

test("a rejection is asked about first, naming the assignment and why it is final", () => {
  assert.match(rejectQuestion(17), /^Reject assignment 17\? This is final for the worker/);
  assert.match(rejectQuestion(17), /They will read:$/);
});
