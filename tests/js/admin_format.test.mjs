// The review page's pure helpers: numbers, point names, report order, job outcomes, bar geometry,
// routes.
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  HAND_JOINTS, barLayout, canRetry, costCells, jobOutcome, orderReports,
  pageOf, parseRoute, percent, pointNames, px, tallyReports, when,
} from "../../frontend/admin/core/format.js";

test("px writes pixels with one decimal and a dash where unknown", () => {
  assert.equal(px(3.14159), "3.1 px");
  assert.equal(px(0), "0.0 px");
  assert.equal(px(12.96), "13.0 px");
  assert.equal(px(null), "–");
  assert.equal(px(undefined), "–");
  assert.equal(px(Number.NaN), "–");
});

test("percent writes a fraction as a percentage with one decimal", () => {
  assert.equal(percent(0.125), "12.5%");
  assert.equal(percent(1), "100.0%");
  assert.equal(percent(0), "0.0%");
  assert.equal(percent(null), "–");
});

test("when reads ISO times with or without a zone as UTC minutes", () => {
  assert.equal(when("2026-11-23T14:05:59.123456"), "2026-11-23 14:05");
  assert.equal(when("2026-11-23T14:05:00+02:00"), "2026-11-23 12:05");
  assert.equal(when("2026-11-23T14:05:00Z"), "2026-11-23 14:05");
  assert.equal(when(null), "–");
  assert.equal(when("not a date"), "–");
});

test("hand joints follow DexYCB order: wrist, then each finger from thumb to little", () => {
  assert.equal(HAND_JOINTS.length, 21);
  assert.equal(HAND_JOINTS[0], "wrist");
  assert.deepEqual(HAND_JOINTS.slice(1, 5), ["thumb_mcp", "thumb_pip", "thumb_dip", "thumb_tip"]);
  assert.equal(HAND_JOINTS[5], "index_mcp");
  assert.equal(HAND_JOINTS[20], "little_tip");
});

test("pointNames names hand joints and object landmarks", () => {
  assert.deepEqual(pointNames("hand:0", 21), HAND_JOINTS);
  assert.deepEqual(pointNames("object:2", 2), ["landmark_1", "landmark_2"]);
  // A hand report of an unexpected size is not given wrong joint names.
  assert.deepEqual(pointNames("hand:0", 3), ["landmark_1", "landmark_2", "landmark_3"]);
});

const REPORTS = [
  { assignment_id: 4, outcome: "approve", action: "recorded", provisional: false },
  { assignment_id: 7, outcome: "review", action: null, provisional: false },
  { assignment_id: 2, outcome: "reject", action: "rejected", provisional: false },
  { assignment_id: 9, outcome: "review", action: "approved", provisional: false },
  { assignment_id: 5, outcome: "review", action: null, provisional: true },
];

test("orderReports puts work waiting for an admin first, then by assignment", () => {
  assert.deepEqual(orderReports([...REPORTS]).map((r) => r.assignment_id), [5, 7, 2, 4, 9]);
});

test("orderReports keeps only the outcome asked for and leaves its input as it was", () => {
  const input = [...REPORTS];
  assert.deepEqual(orderReports(input, "review").map((r) => r.assignment_id), [5, 7, 9]);
  assert.deepEqual(orderReports(input, "approve").map((r) => r.assignment_id), [4]);
  assert.deepEqual(input.map((r) => r.assignment_id), [4, 7, 2, 9, 5]);
});

test("tallyReports counts outcomes and the reports awaiting an admin", () => {
  assert.deepEqual(tallyReports(REPORTS), { approve: 1, review: 3, reject: 1, waiting: 2 });
  assert.deepEqual(tallyReports([]), { approve: 0, review: 0, reject: 0, waiting: 0 });
});

test("canRetry allows only failed and waiting jobs", () => {
  for (const status of ["failed", "waiting"]) assert.equal(canRetry({ status }), true);
  for (const status of ["queued", "running", "retrying", "done"]) {
    assert.equal(canRetry({ status }), false);
  }
});

const TRACEBACK = "Traceback (most recent call last):\n  File \"flows.py\", line 3\n"
  + "ValueError: capture 4 has no frames\n";

test("jobOutcome shows the API's one-line message, toned by status, the error behind it", () => {
  const line = "qc: hand:0 scored 6: 4 approve, 2 review, 0 reject";
  assert.deepEqual(jobOutcome({ kind: "qc", status: "done", message: `  ${line} `, error: null }),
    { line, tone: "", full: line });
  const waiting = "solve: waiting: 27 of 32 tasks not accepted yet";
  assert.deepEqual(jobOutcome({ kind: "solve", status: "waiting", message: waiting }),
    { line: waiting, tone: "warn", full: waiting });
  assert.deepEqual(
    jobOutcome({ kind: "qc", status: "failed", message: "qc: failed: boom", error: TRACEBACK }),
    { line: "qc: failed: boom", tone: "error", full: TRACEBACK.trim() });
});

test("jobOutcome without a message says a failing job's last error line", () => {
  for (const [status, tone] of [["failed", "error"], ["retrying", "error"], ["waiting", "warn"]]) {
    assert.deepEqual(jobOutcome({ kind: "frame_stats", status, error: TRACEBACK }), {
      line: `frame_stats: ${status}: ValueError: capture 4 has no frames`, tone,
      full: TRACEBACK.trim(),
    });
  }
});

test("jobOutcome without a message says a done job's result message, else its status", () => {
  assert.deepEqual(
    jobOutcome({ kind: "sync", status: "done", result: { message: "3 assignments synced" } }),
    { line: "sync: 3 assignments synced", tone: "", full: "sync: 3 assignments synced" });
  // A result message counts only once the job is done, and only if it is text.
  assert.equal(jobOutcome({ kind: "sync", status: "running", result: { message: "half" } }).line,
    "sync: running");
  assert.equal(jobOutcome({ kind: "sync", status: "done", result: { message: 3 } }).line,
    "sync: done");
  assert.deepEqual(jobOutcome({ kind: "qc", status: "queued", result: null, error: null }),
    { line: "qc: queued", tone: "", full: "qc: queued" });
  // An old error of a job queued again is not its line, but stays behind it.
  assert.deepEqual(jobOutcome({ kind: "qc", status: "queued", error: TRACEBACK }),
    { line: "qc: queued", tone: "", full: TRACEBACK.trim() });
});

test("barLayout scales the largest value to the plot height and flattens unknowns", () => {
  const size = { width: 400, height: 100, gap: 0 };
  const layout = barLayout([2, null, 8, 4], ["a", "b", "c", "d"], size);
  assert.equal(layout.max, 8);
  assert.deepEqual(layout.bars.map((b) => b.height), [25, 0, 100, 50]);
  assert.deepEqual(layout.bars.map((b) => b.y), [75, 100, 0, 50]);
  assert.deepEqual(layout.bars.map((b) => b.x), [0, 100, 200, 300]);
  assert.deepEqual(layout.bars.map((b) => b.width), [100, 100, 100, 100]);
  assert.equal(layout.bars[1].value, null);
  assert.equal(layout.bars[2].label, "c");
});

test("barLayout of only unknown or zero values draws no heights", () => {
  const layout = barLayout([null, 0], ["a", "b"], { width: 10, height: 10 });
  assert.equal(layout.max, 0);
  assert.deepEqual(layout.bars.map((b) => b.height), [0, 0]);
});

test("barLayout refuses labels that do not match the values", () => {
  assert.throws(() => barLayout([1, 2], ["a"]), /2 values but 1 labels/);
});

test("costCells writes a cost line's key and money columns in dollars", () => {
  const line = { key: "W1", spent: "1.2", spent_rewards: "1", spent_bonuses: "0",
    spent_fees: "0.2", committed: "0.6", committed_rewards: "0.5", committed_bonuses: "0",
    committed_fees: "0.1" };
  assert.deepEqual(costCells(line),
    ["W1", "$1.20", "$1.00", "$0.00", "$0.20", "$0.60", "$0.50", "$0.00", "$0.10"]);
});

test("parseRoute maps each hash to its view, sequence, assignment and page", () => {
  const none = { sequence: null, assignment: null, offset: 0 };
  assert.deepEqual(parseRoute(""), { view: "sequences", ...none });
  assert.deepEqual(parseRoute("#/sequences"), { view: "sequences", ...none });
  assert.deepEqual(parseRoute("#/sequences/3"),
    { view: "sequence", sequence: 3, assignment: null, offset: 0 });
  assert.deepEqual(parseRoute("#/sequences/3/reports/17"),
    { view: "report", sequence: 3, assignment: 17, offset: 0 });
  assert.deepEqual(parseRoute("#/sequences/3/reports/x"),
    { view: "sequence", sequence: 3, assignment: null, offset: 0 });
  assert.deepEqual(parseRoute("#/sequences/abc"), { view: "sequences", ...none });
  assert.deepEqual(parseRoute("#/workers"), { view: "workers", ...none });
  assert.deepEqual(parseRoute("#/jobs"), { view: "jobs", ...none });
  assert.deepEqual(parseRoute("#/costs"), { view: "costs", ...none });
  assert.deepEqual(parseRoute("#/crowd"), { view: "crowd", ...none });
  assert.deepEqual(parseRoute("#/crowd/3"), { view: "crowd", ...none, sequence: 3 });
  assert.deepEqual(parseRoute("#/crowd/x"), { view: "crowd", ...none });
  assert.deepEqual(parseRoute("#/team"), { view: "team", ...none });
  assert.deepEqual(parseRoute("#/nowhere"), { view: "sequences", ...none });
  // Pages of the paged listings; a page address that is not a number is the first page.
  assert.deepEqual(parseRoute("#/sequences/from/50"), { view: "sequences", ...none, offset: 50 });
  assert.deepEqual(parseRoute("#/workers/from/200"), { view: "workers", ...none, offset: 200 });
  assert.deepEqual(parseRoute("#/sequences/from/-5"), { view: "sequences", ...none });
  assert.deepEqual(parseRoute("#/workers/from/x"), { view: "workers", ...none });
  assert.deepEqual(parseRoute("#/sequences/from/99999999999999"),
    { view: "sequences", ...none, offset: 2 ** 31 - 1 });
  assert.deepEqual(parseRoute("#/jobs/from/50"), { view: "jobs", ...none });
});

test("pageOf says which rows a page shows and where the pages around it start", () => {
  assert.deepEqual(pageOf(0, 50, 50, true), { first: 1, last: 50, previous: null, next: 50 });
  assert.deepEqual(pageOf(50, 50, 50, true), { first: 51, last: 100, previous: 0, next: 100 });
  assert.deepEqual(pageOf(100, 50, 7, false), { first: 101, last: 107, previous: 50, next: null });
  assert.deepEqual(pageOf(0, 50, 3, false), { first: 1, last: 3, previous: null, next: null });
  // An address past the end: nothing shown, a way back.
  assert.deepEqual(pageOf(30, 50, 0, false), { first: 0, last: 30, previous: 0, next: null });
});

