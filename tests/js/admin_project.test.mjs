// The admin page's project-control helpers: progress lines and bars, publish costs,
// worker sparklines and the job table's whole results and filters.
import assert from "node:assert/strict";
import { test } from "node:test";

import { costCells } from "../../frontend/admin/core/format.js";
import {
  TASK_STATES, costLine, inCurrency, jobDetail, jobQuery, progressLine, progressSegments, solveLine,
  sparkline, taskCounts,
} from "../../frontend/admin/core/project-format.js";

test("progressLine counts accepted tasks of all, then the rest from the furthest state", () => {
  const counts = { open: 1, published: 2, submitted: 0, "in review": 1, accepted: 3 };
  assert.equal(progressLine({ state: "in progress", counts }),
    "3 of 7 accepted · 1 in review · 2 published · 1 open");
  assert.equal(progressLine({ state: "no tasks", counts: {} }), "no tasks yet");
  assert.equal(progressLine({ state: "accepted", counts: { accepted: 4 } }), "4 of 4 accepted");
  // Views the adaptive policy holds back are open tasks, named apart from the published ones.
  assert.equal(progressLine({ state: "accepted", counts: { accepted: 6, open: 2 }, held: 2 }),
    "6 of 6 accepted · 2 held back");
  assert.equal(progressLine({ state: "in progress", counts: { published: 5, open: 3 }, held: 2 }),
    "0 of 6 accepted · 5 published · 1 open · 2 held back");
});

test("solveLine says whether the current labels are solved", () => {
  const p = (/** @type {any} */ solve) => ({ state: "accepted", counts: {}, solve });
  assert.equal(solveLine(p(null)), "not solved yet");
  assert.equal(solveLine(p({ run_id: 3, status: "done", labels: "current" })), "solved (run 3)");
  assert.equal(solveLine(p({ run_id: 3, status: "done", labels: "outdated" })),
    "solve run 3 done, labels changed since");
  assert.equal(solveLine(p({ run_id: 4, status: "failed", labels: "current" })),
    "solve run 4 failed");
});

test("progressSegments give each present state its share in state order", () => {
  const segments = progressSegments({ accepted: 1, open: 3 });
  assert.deepEqual(segments.map((s) => [s.state, s.count, s.percent]),
    [["open", 3, 75], ["accepted", 1, 25]]);
  assert.deepEqual(TASK_STATES, ["open", "published", "submitted", "in review", "accepted"]);
});

test("taskCounts names the HITs and each kind of assignment a cell has", () => {
  assert.equal(taskCounts({ hits: 1, assignments: { approved: 1, submitted: 0, rejected: 2,
    working: 1 } }), "1 HIT, 1 approved, 2 rejected, 1 working");
  assert.equal(taskCounts({ hits: 0, assignments: {} }), "0 HITs");
});

test("costLine writes the HIT count and the cost before anything is published", () => {
  const cost = { hits: 4, assignments_per_hit: 1, reward: "0.40", fee_per_assignment: "0.08",
    rewards: "1.60", fees: "0.32", total: "1.92" };
  assert.equal(costLine({ cost }),
    "4 HITs × 1 assignment at $0.40 + $0.08 fee: rewards $1.60 + fees $0.32 = $1.92");
  assert.equal(costLine({ cost: { ...cost, hits: 1, assignments_per_hit: 3 } }).slice(0, 18),
    "1 HIT × 3 assignme");
  assert.match(costLine({ cost: { ...cost, hits: 0 } }), /^Nothing to publish/);
  // A provider that charges in its own currency: every amount in it.
  assert.equal(costLine({ cost: { ...cost, currency: "GBP" } }),
    "4 HITs × 1 assignment at 0.40 GBP + 0.08 GBP fee: rewards 1.60 GBP + fees 0.32 GBP = "
    + "1.92 GBP");
  assert.equal(inCurrency("2.5", "USD"), "$2.50");
});

test("sparkline puts the largest error at the top, unmeasured reports on the base", () => {
  const history = [
    { at: "2026-01-01T00:00:00", outcome: "approve", median_error_px: 2 },
    { at: "2026-01-02T00:00:00", outcome: "review", median_error_px: null },
    { at: "2026-01-03T00:00:00", outcome: "reject", median_error_px: 8 },
  ];
  const { points, max } = sparkline(history, 100, 30);
  assert.equal(max, 8);
  assert.deepEqual(points.map((p) => p.x), [3, 50, 97]);
  assert.deepEqual(points.map((p) => p.y), [30 - 3 - 6, null, 3]);  // 2 px is a quarter of 8
  assert.deepEqual(points.map((p) => p.outcome), ["approve", "review", "reject"]);
  const one = sparkline([history[1]], 100, 30);
  assert.deepEqual([one.points[0].x, one.points[0].y, one.max], [50, null, 0]);
});

test("jobDetail gives the whole error, else the result as indented JSON", () => {
  const error = "Traceback (most recent call last):\n  ...\nValueError: bad frame 3\n";
  assert.equal(jobDetail({ kind: "qc", status: "failed", error, result: null }), error.trim());
  const result = { scored: { approve: 1 }, message: "scored 1" };
  assert.equal(jobDetail({ kind: "qc", status: "done", error: null, result }),
    JSON.stringify(result, null, 2));
  assert.deepEqual(JSON.parse(jobDetail({ kind: "qc", status: "done", result })), result);
  assert.equal(jobDetail({ kind: "solve", status: "queued" }), "solve: queued, no result yet");
});

test("jobQuery filters by status and kind, either left out when empty", () => {
  assert.equal(jobQuery("", ""), "?limit=200");
  assert.equal(jobQuery("failed", "qc"), "?status=failed&kind=qc&limit=200");
  assert.equal(jobQuery("", "export"), "?kind=export&limit=200");
});

test("costCells names a sequence by subject/name, falling back to its key", () => {
  const money = { spent: "0", spent_rewards: "0", spent_bonuses: "0.25", spent_fees: "0.05",
    committed: "0", committed_rewards: "0", committed_bonuses: "0", committed_fees: "0" };
  assert.equal(costCells({ key: "7", name: "s01/grasp", ...money })[0], "s01/grasp");
  assert.equal(costCells({ key: "W1", ...money })[0], "W1");
  assert.equal(costCells({ key: "7", name: "s01/grasp", ...money })[3], "$0.25");
});
