/** Pure helpers of the admin page's project control: task states and progress, publish costs,
 * worker quality over time and the job table's details and filters (no DOM). */

import { dollars, isNumber } from "../../common/format.js";

/** The states of a task, from untouched to done (backend/progress/schemas.py TaskState). */
export const TASK_STATES = ["open", "published", "submitted", "in review", "accepted"];

/**
 * @typedef {{state: string, counts: Record<string, number>, held?: number,
 *            solve?: {run_id: number, status: string, labels: string}|null}} ProgressLike
 */

/**
 * A sequence's progress in one line: "3 of 4 accepted · 1 in review", "no tasks yet"; tasks
 * the adaptive publishing policy holds back (open tasks, counted in ``held``) are named
 * apart: "6 of 6 accepted · 2 held back".
 * @param {ProgressLike} progress   GET /api/sequences/{id}/progress
 */
export function progressLine(progress) {
  const held = progress.held || 0;
  const counts = { ...(progress.counts || {}) };
  counts.open = (counts.open || 0) - held;
  const total = TASK_STATES.reduce((sum, state) => sum + (counts[state] || 0), 0);
  if (!total && !held) return "no tasks yet";
  const rest = TASK_STATES.filter((s) => s !== "accepted" && counts[s] > 0)
    .reverse().map((s) => `${counts[s]} ${s}`);
  if (held) rest.push(`${held} held back`);
  return [`${counts.accepted || 0} of ${total} accepted`, ...rest].join(" · ");
}

/**
 * Whether and how the sequence is solved: "solved (run 3)", "solve run 3 failed",
 * "solve run 2 done, labels changed since", "not solved yet".
 * @param {ProgressLike} progress
 */
export function solveLine(progress) {
  const s = progress.solve;
  if (!s) return "not solved yet";
  if (s.status === "done" && s.labels === "current") return `solved (run ${s.run_id})`;
  if (s.status === "done" && s.labels === "outdated") {
    return `solve run ${s.run_id} done, labels changed since`;
  }
  return `solve run ${s.run_id} ${s.status}`;
}

/**
 * A grid cell's HITs and assignments in a few words: "1 HIT, 1 approved, 1 working".
 * @param {{hits: number, assignments: Record<string, number>}} task
 */
export function taskCounts(task) {
  const a = task.assignments;
  const parts = [`${task.hits} HIT${task.hits === 1 ? "" : "s"}`];
  for (const name of ["approved", "submitted", "rejected", "working"]) {
    if (a[name]) parts.push(`${a[name]} ${name}`);
  }
  return parts.join(", ");
}

/**
 * Segments of a progress bar: each state's share of the tasks, in state order, in percent.
 * @param {Record<string, number>} counts
 * @returns {{state: string, count: number, percent: number}[]}
 */
export function progressSegments(counts) {
  const total = TASK_STATES.reduce((sum, state) => sum + (counts[state] || 0), 0);
  return TASK_STATES.filter((s) => counts[s])
    .map((state) => ({ state, count: counts[state], percent: (100 * counts[state]) / total }));
}

/**
 * A publish's plan or result for people (backend/crowd/schemas.py PublishResult).
 * @param {{cost: {hits: number, assignments_per_hit: number, reward: string,
 *          fee_per_assignment: string, rewards: string, fees: string, total: string,
 *          currency?: string}}} plan  amounts in the provider's currency (unset: USD)
 */
export function costLine(plan) {
  const c = plan.cost;
  if (!c.hits) return "Nothing to publish: every task of this sequence already has a HIT.";
  const hits = `${c.hits} HIT${c.hits === 1 ? "" : "s"}`;
  const each = `${c.assignments_per_hit} assignment${c.assignments_per_hit === 1 ? "" : "s"}`;
  const money = (/** @type {string} */ amount) => inCurrency(amount, c.currency);
  return `${hits} × ${each} at ${money(c.reward)} + ${money(c.fee_per_assignment)} fee: `
    + `rewards ${money(c.rewards)} + fees ${money(c.fees)} = ${money(c.total)}`;
}

/**
 * An amount in a provider's currency: dollars as every page writes them, any other currency
 * by its code ("12.00 GBP").
 * @param {string} amount  @param {string|undefined} currency  ISO 4217; unset: US dollars
 */
export function inCurrency(amount, currency) {
  return !currency || currency === "USD" ? dollars(amount) : `${amount} ${currency}`;
}

/**
 * @typedef {{at: string, outcome: string, median_error_px: number|null}} ReportPoint
 * @typedef {{x: number, y: number|null, outcome: string, error: number|null,
 *            at: string}} SparkPoint
 */

/**
 * A sparkline of a worker's QC reports by date: one point per report, evenly spaced in order,
 * its height the report's median error (px; higher is worse) scaled to the largest; reports
 * without a measured error have y null (drawn as an outcome mark on the base line).
 * @param {ReportPoint[]} history  oldest first
 * @param {number} width  @param {number} height  SVG user units
 * @returns {{points: SparkPoint[], max: number}}
 */
export function sparkline(history, width, height) {
  const errors = history.map((p) => p.median_error_px).filter(isNumber);
  const max = errors.length ? Math.max(...errors) : 0;
  const pad = 3;
  const step = history.length > 1 ? (width - 2 * pad) / (history.length - 1) : 0;
  const points = history.map((p, i) => {
    const e = isNumber(p.median_error_px) ? p.median_error_px : null;
    const y = e === null ? null
      : height - pad - (max > 0 ? (e / max) * (height - 2 * pad) : 0);
    return { x: history.length > 1 ? pad + i * step : width / 2, y, outcome: p.outcome,
      error: e, at: p.at };
  });
  return { points, max };
}

/**
 * A job's whole result or error for reading: the error text as it is, else the result as
 * indented JSON, else what the job waits for.
 * @param {{kind: string, status: string, error?: string|null,
 *          result?: Record<string, unknown>|null}} job
 */
export function jobDetail(job) {
  if (job.error && job.error.trim()) return job.error.trim();
  if (job.result) return JSON.stringify(job.result, null, 2);
  return `${job.kind}: ${job.status}, no result yet`;
}

/** The job statuses the job table filters by (backend/jobs/router.py Status). */
export const JOB_STATUSES = ["queued", "running", "retrying", "waiting", "done", "failed"];

/**
 * The job table's query string for a status and kind filter ("" for either: all).
 * @param {string} status  @param {string} kind
 */
export function jobQuery(status, kind) {
  const params = new URLSearchParams();
  if (status) params.set("status", status);
  if (kind) params.set("kind", kind);
  params.set("limit", "200");
  return `?${params}`;
}
