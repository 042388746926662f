// Readable QC metrics: names, units, explanations and the thresholds each was held to.
import assert from "node:assert/strict";
import { test } from "node:test";

import { basisOf, metricRows, renderMetricList, thresholdOf }
  from "../../frontend/admin/metrics.js";

// Every key the QC code can put in report.metrics (worker/quality/consensus.py, metrics.py,
// landmarks.py, anchored.py, gold.py).
const EMITTED = [
  "median_error_px", "mean_error_px", "p90_error_px", "outlier_fraction", "raw_median_error_px",
  "reference_spread_px", "visibility_disagreement", "occluded_on_surface",
  "visible_behind_surface", "jitter_px", "motion_ratio", "completeness", "visible_fraction",
  "working_time_s", "scored_fraction", "track_jitter_px", "track_jitter_ratio",
  "moved_with_hand", "moved_with_object", "jump_fraction", "max_step_ratio", "static_fraction",
  "anchored_median_px", "anchored_p90_px", "anchored_visible_occluded",
  "anchored_hidden_visible", "anchored_drift_px", "anchored_fraction", "solve_run",
  "landmark_separation_mm", "anchored_facing", "anchored_shown_fraction",
  "decided_fraction", "checks_accepted", "checks_corrected", "own_keyframes",
];

const HAND_REPORT = {
  method: "consensus", target_key: "hand:0", provisional: false,
  metrics: { median_error_px: 4.26, p90_error_px: 6.1, outlier_fraction: 0.02,
    motion_ratio: 0.35, occluded_on_surface: 0.125, working_time_s: 151.4,
    track_jitter_ratio: null, custom_score: 0.5, new_gap_px: 2 },
  thresholds: { "median_error_px.review_above": 3.2, "median_error_px.reject_above": 12,
    "p90_error_px.review_above": 6.5, "p90_error_px.reject_above": 30,
    "motion_ratio.review_below": 0.4, "motion_ratio.reject_below": 0.1,
    "motion_ratio.review_above": 3, "occluded_on_surface.review_above": 0.1,
    "occluded_on_surface.reject_above": 0.3 },
};

test("every metric the QC code emits has a human name, a unit and an explanation", () => {
  const report = { method: "consensus", target_key: "hand:0",
    metrics: Object.fromEntries(EMITTED.map((name) => [name, 0.5])), thresholds: {} };
  const rows = metricRows(report);
  assert.deepEqual(rows.map((r) => r.name).sort(), [...EMITTED].sort());
  for (const row of rows) {
    assert.notEqual(row.label, row.name, row.name);
    assert.ok(!row.label.includes("_"), `${row.name}: ${row.label}`);
    assert.ok(row.explain.length > 20 && !row.explain.includes("\n"), row.name);
    assert.equal(row.threshold, null);
    assert.equal(row.over, false);
  }
  const byName = Object.fromEntries(rows.map((r) => [r.name, r]));
  assert.equal(byName.median_error_px.label, "Median error");
  assert.equal(byName.median_error_px.unit, "px");
  assert.equal(byName.outlier_fraction.unit, "%");
  assert.equal(byName.working_time_s.unit, "s");
  assert.equal(byName.motion_ratio.unit, "×");
});

test("values are written with their units", () => {
  const rows = Object.fromEntries(metricRows(HAND_REPORT).map((r) => [r.name, r]));
  assert.equal(rows.median_error_px.value, "4.3 px");
  assert.equal(rows.outlier_fraction.value, "2.0%");
  assert.equal(rows.occluded_on_surface.value, "12.5%");
  assert.equal(rows.working_time_s.value, "151 s");
  assert.equal(rows.motion_ratio.value, "0.35×");
  assert.equal(rows.track_jitter_ratio.value, "–");
});

test("the threshold held to is written and a crossed one marks the row over", () => {
  const rows = Object.fromEntries(metricRows(HAND_REPORT).map((r) => [r.name, r]));
  assert.equal(rows.median_error_px.threshold, "review above 3.2 px; reject above 12.0 px");
  assert.equal(rows.median_error_px.over, true);
  assert.equal(rows.p90_error_px.over, false);  // 6.1 within 6.5
  assert.equal(rows.motion_ratio.threshold, "review below 0.40× or above 3.00×; reject below 0.10×");
  assert.equal(rows.motion_ratio.over, true);  // 0.35 < 0.4
  assert.equal(rows.occluded_on_surface.threshold, "review above 10.0%; reject above 30.0%");
  assert.equal(rows.occluded_on_surface.over, true);
  assert.equal(rows.working_time_s.threshold, null);
  assert.equal(rows.working_time_s.over, false);
});

test("a value exactly at its threshold has not crossed it, an unknown value never has", () => {
  const limits = { "median_error_px.review_above": 3.2 };
  assert.equal(thresholdOf("median_error_px", 3.2, "px", limits).over, false);
  assert.equal(thresholdOf("median_error_px", 3.21, "px", limits).over, true);
  assert.equal(thresholdOf("median_error_px", null, "px", limits).over, false);
  assert.equal(thresholdOf("motion_ratio", 0.05, "×", { "motion_ratio.reject_below": 0.1 }).over,
    true);
});

test("known metrics come first in their fixed order, unknown keys after, readable", () => {
  const rows = metricRows(HAND_REPORT);
  assert.deepEqual(rows.map((r) => r.name), ["median_error_px", "p90_error_px",
    "outlier_fraction", "occluded_on_surface", "motion_ratio", "track_jitter_ratio",
    "working_time_s", "custom_score", "new_gap_px"]);
  const custom = rows.find((r) => r.name === "custom_score");
  assert.deepEqual([custom?.label, custom?.value, custom?.unit], ["Custom score", "0.50", ""]);
  const gap = rows.find((r) => r.name === "new_gap_px");
  assert.deepEqual([gap?.label, gap?.value, gap?.unit], ["New gap", "2.0 px", "px"]);
});

test("explanations follow what the report was judged against", () => {
  const metrics = { median_error_px: 2, visibility_disagreement: 0.1 };
  const hand = metricRows({ method: "consensus", target_key: "hand:0", metrics });
  const object = metricRows({ method: "consensus", target_key: "object:1", metrics });
  const gold = metricRows({ method: "gold", target_key: "hand:0", metrics });
  assert.match(hand[0].explain, /other camera views/);
  assert.match(object[0].explain, /outline/);
  assert.match(gold[0].explain, /gold/);
  assert.match(hand[1].explain, /depth camera/);
  assert.match(gold[1].explain, /gold/);
  assert.equal(basisOf({ method: "gold", target_key: "object:0" }), "gold");
  assert.equal(basisOf({}), "hand");
});

test("a report without metrics or thresholds gives no rows", () => {
  assert.deepEqual(metricRows({}), []);
  assert.deepEqual(metricRows({ metrics: {}, thresholds: {} }), []);
});

/** The least of a DOM that renderMetricList writes with. */
class FakeNode {
  /** @param {string} tag */
  constructor(tag) {
    this.tagName = tag.toUpperCase();
    /** @type {FakeNode[]} */
    this.children = [];
    /** @type {Record<string, string>} */
    this.attributes = {};
    this.textContent = "";
    this.title = "";
    this.className = "";
    this.ownerDocument = FAKE_DOCUMENT;
  }

  /** @param {FakeNode[]} nodes */
  append(...nodes) { this.children.push(...nodes); }

  /** @param {FakeNode[]} nodes */
  replaceChildren(...nodes) { this.children = nodes; }

  /** @param {string} name @param {string} value */
  setAttribute(name, value) { this.attributes[name] = value; }

  /** @returns {string} */
  get text() { return this.textContent + this.children.map((c) => c.text).join(""); }
}

const FAKE_DOCUMENT = { /** @param {string} tag */ createElement: (tag) => new FakeNode(tag) };

test("renderMetricList writes a name, value, threshold and over flag per metric", () => {
  const dl = new FakeNode("dl");
  dl.append(new FakeNode("dt"));  // what was there before is replaced
  const rows = renderMetricList(/** @type {any} */ (dl), HAND_REPORT);
  assert.equal(dl.children.length, rows.length * 2);
  const [dt, dd] = dl.children;
  assert.equal(dt.tagName, "DT");
  assert.equal(dt.textContent, "Median error");
  assert.match(dt.title, /other camera views/);
  assert.equal(dd.attributes["data-metric"], "median_error_px");
  assert.equal(dd.attributes["data-over"], "true");
  assert.match(dd.text,
    /^⚠ 4\.3 px \(crossed: review above 3\.2 px; reject above 12\.0 px\)/);
  const p90 = dl.children[3];
  assert.equal(p90.attributes["data-over"], "false");
  assert.match(p90.text, /^6\.1 px \(review above 6\.5 px; reject above 30\.0 px\)/);
  const time = dl.children[rows.findIndex((r) => r.name === "working_time_s") * 2 + 1];
  assert.equal(time.attributes["data-over"], "false");
  assert.match(time.text, /^151 s(?! \()/);
});

test("an object's landmarks read their separation in mm against the fixed minimum", () => {
  const rows = Object.fromEntries(metricRows({
    method: "consensus", target_key: "object:1",
    metrics: { landmark_separation_mm: 1.46, anchored_facing: 0.88, solve_run: null },
    thresholds: { "landmark_separation_mm.reject_below": 15 } }).map((r) => [r.name, r]));
  assert.equal(rows.landmark_separation_mm.value, "1.5 mm");
  assert.equal(rows.landmark_separation_mm.threshold, "reject below 15.0 mm");
  assert.equal(rows.landmark_separation_mm.over, true);
  assert.equal(rows.anchored_facing.value, "0.88");
  assert.equal(rows.solve_run.value, "–");
});
