/** Pure helpers of the admins' review page: numbers, point names, report order, chart layout
 * and the routes of its hash (no DOM). */

import { NONE, dollars, isNumber } from "../../common/format.js";

const FINGERS = ["thumb", "index", "middle", "ring", "little"];
const JOINT_SUFFIXES = ["mcp", "pip", "dip", "tip"];

/** The 21 hand joints in DexYCB order (worker/hand/joints.py JOINT_NAMES). */
export const HAND_JOINTS = ["wrist",
  ...FINGERS.flatMap((finger) => JOINT_SUFFIXES.map((suffix) => `${finger}_${suffix}`))];

/** The outcomes of a QC report, from clear pass to clear fail. */
export const OUTCOMES = ["approve", "review", "reject"];

/**
 * An image distance: "3.2 px", or a dash where unknown.
 * @param {number|null|undefined} value  pixels
 */
export function px(value) {
  return isNumber(value) ? `${value.toFixed(1)} px` : NONE;
}

/**
 * A fraction as a percentage with one decimal: 0.125 -> "12.5%".
 * @param {number|null|undefined} value  0..1
 */
export function percent(value) {
  return isNumber(value) ? `${(value * 100).toFixed(1)}%` : NONE;
}

/**
 * A date and time as the API writes it (ISO 8601, UTC when no zone) for people: "2026-11-23 14:05".
 * @param {string|null|undefined} iso
 */
export function when(iso) {
  if (!iso) return NONE;
  const text = /[zZ]|[+-]\d\d:\d\d$/.test(iso) ? iso : `${iso}Z`;
  const date = new Date(text);
  if (Number.isNaN(date.getTime())) return NONE;
  return date.toISOString().slice(0, 16).replace("T", " ");
}

/**
 * The names of a target's points: the 21 hand joints, or "landmark_1", "landmark_2", ...
 * @param {string} targetKey  "hand:0" or "object:1"
 * @param {number} count      points in the report (P)
 * @returns {string[]}
 */
export function pointNames(targetKey, count) {
  const hand = targetKey.startsWith("hand:") && count === HAND_JOINTS.length;
  return Array.from({ length: count }, (_, i) => (hand ? HAND_JOINTS[i] : `landmark_${i + 1}`));
}

/**
 * @typedef {{assignment_id: number, outcome: string, action: string|null,
 *            provisional: boolean}} ReportLike
 */

/**
 * Work that waits for an admin: QC left it for review and nobody acted on it yet.
 * @param {ReportLike} report
 */
export function awaitsAdmin(report) {
  return report.outcome === "review" && !report.action;
}

/**
 * Reports to show: those of ``outcome`` (all when empty), the ones awaiting an admin first,
 * then by assignment.
 * @template {ReportLike} T
 * @param {T[]} reports
 * @param {string} [outcome]  "approve" | "review" | "reject" | "" (all)
 * @returns {T[]}
 */
export function orderReports(reports, outcome = "") {
  return reports
    .filter((r) => !outcome || r.outcome === outcome)
    .sort((a, b) => Number(awaitsAdmin(b)) - Number(awaitsAdmin(a))
      || a.assignment_id - b.assignment_id);
}

/**
 * Counts of reports per outcome, and how many await an admin.
 * @param {ReportLike[]} reports
 * @returns {{approve: number, review: number, reject: number, waiting: number}}
 */
export function tallyReports(reports) {
  const tally = { approve: 0, review: 0, reject: 0, waiting: 0 };
  for (const r of reports) {
    if (r.outcome in tally) tally[/** @type {"approve"|"review"|"reject"} */ (r.outcome)] += 1;
    if (awaitsAdmin(r)) tally.waiting += 1;
  }
  return tally;
}

/**
 * Whether an admin may re-run a job (the API refuses queued, running and retrying ones).
 * @param {{status: string}} job
 */
export function canRetry(job) {
  return job.status === "failed" || job.status === "waiting";
}

/** The tone of a job's outcome line by its status: trouble, a wait, or plain. */
const JOB_TONES = /** @type {Record<string, string>} */ ({
  failed: "error", retrying: "error", waiting: "warn",
});

/**
 * @typedef {{kind: string, status: string, error?: string|null,
 *            result?: Record<string, unknown>|null, message?: string}} JobLike
 */

/**
 * A job's result or error in one line for people, its tone, and the full text behind it.
 * The line is the API's ``message`` ("qc: hand:0 scored 6: 4 approve, 2 review, 0 reject",
 * "solve: waiting: 27 of 32 tasks not accepted yet"); where a reply has none, it is made the
 * same way from the error's last line or the result's own message.
 * @param {JobLike} job   GET /api/jobs
 * @returns {{line: string, tone: string, full: string}}
 */
export function jobOutcome(job) {
  const error = (job.error || "").trim();
  const lastLine = error.split("\n").pop() || "";
  const said = typeof job.result?.message === "string" ? job.result.message : "";
  let line = (job.message || "").trim();
  if (!line) {
    if (lastLine && JOB_TONES[job.status]) line = `${job.kind}: ${job.status}: ${lastLine.trim()}`;
    else if (said && job.status === "done") line = `${job.kind}: ${said}`;
    else line = `${job.kind}: ${job.status}`;
  }
  return { line, tone: JOB_TONES[job.status] || "", full: error || line };
}

/**
 * @typedef {{label: string, value: number|null, x: number, y: number, width: number,
 *            height: number}} Bar
 * @typedef {{width: number, height: number, max: number, bars: Bar[]}} BarLayout
 */

/**
 * Geometry of a vertical bar chart in SVG user units: one bar per value, scaled so the largest
 * value fills the plot height; unknown values (null) get a zero-height bar.
 * @param {(number|null)[]} values
 * @param {string[]} labels   one per value
 * @param {{width?: number, height?: number, gap?: number}} [size]
 * @returns {BarLayout}
 */
export function barLayout(values, labels, size = {}) {
  const width = size.width ?? 600, height = size.height ?? 160, gap = size.gap ?? 2;
  if (labels.length !== values.length) {
    throw new Error(`barLayout: ${values.length} values but ${labels.length} labels`);
  }
  const known = values.filter(isNumber);
  const max = known.length ? Math.max(...known) : 0;
  const step = values.length ? width / values.length : 0;
  const bars = values.map((value, i) => {
    const h = isNumber(value) && max > 0 ? (Math.max(value, 0) / max) * height : 0;
    return { label: labels[i], value: isNumber(value) ? value : null,
      x: i * step + gap / 2, y: height - h, width: Math.max(step - gap, 1), height: h };
  });
  return { width, height, max, bars };
}

/**
 * @typedef {{view: "sequences"|"sequence"|"report"|"workers"|"jobs"|"costs"|"crowd"|"team",
 *            sequence: number|null, assignment: number|null, offset: number}} Route
 */

/**
 * The page's place from its hash: #/sequences, #/sequences/from/<offset>, #/sequences/<id>,
 * #/sequences/<id>/reports/<assignment>, #/workers, #/workers/from/<offset>, #/jobs, #/costs,
 * #/crowd, #/crowd/<sequence id> (its units only), #/team.
 * ``offset``: where the page of a paged listing (sequences, workers) starts; 0 elsewhere.
 * @param {string} hash
 * @returns {Route}
 */
export function parseRoute(hash) {
  const parts = hash.replace(/^#\/?/, "").split("/");
  const id = (/** @type {string|undefined} */ text) =>
    (text && /^\d+$/.test(text) ? Number(text) : null);
  const [view = "", seq, sub, aid] = parts;
  const none = { sequence: null, assignment: null, offset: 0 };
  const offset = seq === "from" ? Math.min(id(sub) ?? 0, MAX_OFFSET) : 0;
  if (view === "workers") return { view, ...none, offset };
  if (view === "crowd") return { view, ...none, sequence: id(seq) };
  if (["jobs", "costs", "team"].includes(view)) {
    return { view: /** @type {Route["view"]} */ (view), ...none };
  }
  const sequence = view === "sequences" ? id(seq) : null;
  if (sequence !== null && sub === "reports" && id(aid) !== null) {
    return { view: "report", sequence, assignment: id(aid), offset: 0 };
  }
  if (sequence !== null) return { view: "sequence", sequence, assignment: null, offset: 0 };
  return { view: "sequences", ...none, offset: view === "sequences" ? offset : 0 };
}

/** The largest offset the API takes (a 32-bit integer). */
const MAX_OFFSET = 2 ** 31 - 1;

/**
 * Where a page of a listing sits: its first and last row (1-based) and the offsets of the
 * pages before and after it (null where there is none).
 * @param {number} offset  the page's first row, 0-based
 * @param {number} size  rows a page holds
 * @param {number} shown  rows on this page
 * @param {boolean} more  whether rows follow this page
 */
export function pageOf(offset, size, shown, more) {
  return {
    first: shown ? offset + 1 : 0, last: offset + shown,
    previous: offset > 0 ? Math.max(offset - size, 0) : null,
    next: more ? offset + size : null,
  };
}

/** The money columns of a cost line (backend/crowd/schemas.py CostLine), with headings. */
export const COST_COLUMNS = [
  ["spent", "Spent"], ["spent_rewards", "rewards"], ["spent_bonuses", "bonuses"],
  ["spent_fees", "fees"], ["committed", "Committed"], ["committed_rewards", "rewards"],
  ["committed_bonuses", "bonuses"], ["committed_fees", "fees"],
];

/**
 * A cost line as table cells: its name (a sequence's subject/name; the key where it has
 * none), then each money column in dollars.
 * @param {Record<string, string>} line
 * @returns {string[]}
 */
export function costCells(line) {
  return [line.name || line.key, ...COST_COLUMNS.map(([name]) => dollars(line[name]))];
}

