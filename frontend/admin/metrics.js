/** QC metrics for people: each metric of a report (GET /api/qc/reports/{id}) as a named row
 * with its value, unit, a one-line explanation and the threshold it was held to (no DOM but
 * renderMetricList, which writes the rows into a <dl> of any document).
 *
 * The metric names are those the QC code emits: hand labels against the other views
 * (worker/quality/consensus.py, metrics.py), object landmarks on their own and against the
 * solved object (landmarks.py, anchored.py) and training clips against their gold (gold.py).
 * The thresholds are the report's own (worker/quality/decide.py): keys
 * "<metric>.<review|reject>_<above|below>", crossed when the value is beyond them. */

import { NONE, isNumber } from "../common/format.js";

/**
 * @typedef {Object} MetricRow
 * @property {string} name       the metric's key in report.metrics
 * @property {string} label      its human name
 * @property {string} value      formatted with its unit ("3.2 px", "12.5%", "150 s"); "–" unknown
 * @property {string} unit       "px", "mm", "%", "s", "px/frame²", "×" or "" (a count, an
 *                               identifier or a cosine)
 * @property {string} explain    one line: what the number measures
 * @property {string|null} threshold  the limits it was held to ("review above 3.0 px; reject
 *                               above 12.0 px"), null where the report holds it to none
 * @property {boolean} over      the value crossed one of those limits
 */

/**
 * What a report was judged against, which changes what some metrics mean.
 * @typedef {"hand"|"object"|"gold"} Basis
 */

/**
 * @typedef {Object} MetricInfo
 * @property {string} label
 * @property {"px"|"mm"|"%"|"s"|"px/frame²"|"×"|""} unit
 * @property {string | Partial<Record<Basis, string>> & {any?: string}} explain
 */

/** @type {Record<string, MetricInfo>} in the order the rows are listed */
const METRICS = {
  median_error_px: { label: "Median error", unit: "px", explain: {
    hand: "Half of the visible points lie farther than this from where the other camera views "
      + "place them (scaled to how tightly those views fix each point).",
    object: "Half of the landmarks lie farther than this from the object's outline.",
    gold: "Half of the visible points lie farther than this from the known (gold) labels.",
  } },
  p90_error_px: { label: "90th percentile error", unit: "px", explain: {
    hand: "A tenth of the visible points lie farther than this from where the other views "
      + "place them.",
    object: "A tenth of the landmarks lie farther than this from the object's outline.",
    gold: "A tenth of the visible points lie farther than this from the gold labels.",
  } },
  mean_error_px: { label: "Mean error", unit: "px", explain: {
    hand: "Average distance of the visible points from where the other views place them.",
    object: "Average distance of the landmarks from the object's outline.",
    gold: "Average distance of the visible points from the gold labels.",
  } },
  outlier_fraction: { label: "Far-off points", unit: "%", explain: {
    hand: "Share of the judged points far from where the other views place them.",
    object: "Share of the landmarks more than 3 px off the object's outline.",
    gold: "Share of the visible points more than 10 px from the gold labels.",
  } },
  raw_median_error_px: { label: "Median raw error", unit: "px", explain:
    "The median error in plain pixels, before scaling by how well the other views fix each "
    + "point." },
  reference_spread_px: { label: "Reference uncertainty", unit: "px", explain:
    "How loosely the other views fix the points this label is compared with (median, per "
    + "axis)." },
  anchored_median_px: { label: "Median error on the object", unit: "px", explain:
    "Half of the landmark positions lie farther than this from the point of the solved "
    + "object they mark." },
  anchored_p90_px: { label: "90th percentile error on the object", unit: "px", explain:
    "A tenth of the landmark positions lie farther than this from the solved object's point." },
  anchored_drift_px: { label: "Drift on the object", unit: "px", explain:
    "How much farther the landmarks are from their object point at the end of the clip than "
    + "at its start." },
  anchored_fraction: { label: "Landmarks on the object", unit: "%", explain:
    "Share of the landmarks that could be tied to a point of the solved object." },
  landmark_separation_mm: { label: "Landmarks apart on the object", unit: "mm", explain:
    "Distance between the two landmarks' points on the object's surface: two landmarks on one "
    + "spot fix nothing that one does not." },
  anchored_facing: { label: "Landmarks in plain view", unit: "", explain:
    "How squarely the surface under each landmark faces the camera (cosine of the angle, 1 = "
    + "head-on, 0 = edge-on; the least over the landmarks)." },
  anchored_shown_fraction: { label: "Landmarks shown", unit: "%", explain:
    "Of the frames where the object's pose is known, the share in which each landmark's "
    + "point can be seen (the least over the landmarks)." },
  anchored_visible_occluded: { label: "Seen landmarks marked occluded", unit: "%", explain:
    "Of the frames where the solved object shows a landmark's point, the share marked "
    + "occluded." },
  anchored_hidden_visible: { label: "Hidden landmarks marked visible", unit: "%", explain:
    "Of the frames where the object turns a landmark's point away or something covers it, "
    + "the share marked visible." },
  visibility_disagreement: { label: "Visibility disagreement", unit: "%", explain: {
    any: "Share of the points the depth camera can judge (on the visible surface, or behind "
      + "an object) whose visible/occluded flag it contradicts.",
    gold: "Share of the points whose visible/occluded flag differs from the gold labels'.",
  } },
  occluded_on_surface: { label: "Seen points marked occluded", unit: "%", explain: {
    any: "Of the points the depth camera sees on the visible surface, the share marked "
      + "occluded.",
    gold: "Of the points visible in the gold labels, the share marked occluded.",
  } },
  visible_behind_surface: { label: "Covered points marked visible", unit: "%", explain: {
    any: "Of the points the depth camera sees covered by something other than the hand "
      + "itself, the share marked visible; measured once at least 10 such points were seen.",
    gold: "Of the points occluded in the gold labels, the share marked visible.",
  } },
  motion_ratio: { label: "Motion ratio", unit: "×", explain: {
    any: "How far the points travel compared with the reference: about 1 for a good label, "
      + "near 0 for a frozen one, far above 1 for random clicks.",
    object: "How far the landmarks travel compared with the object's outline: about 1 for a "
      + "good label, near 0 for a frozen one.",
  } },
  moved_with_hand: { label: "Moved with the hand", unit: "%", explain:
    "How far the points travel compared with the hand's motion in the other views' tracks "
    + "(100% = as far or farther)." },
  moved_with_object: { label: "Moved with the object", unit: "%", explain:
    "How far the landmarks travel compared with the object's motion in the other views' "
    + "tracks (100% = as far or farther)." },
  jitter_px: { label: "Jitter", unit: "px/frame²", explain: {
    any: "Frame-to-frame shake of the label's offset from the reference (RMS second "
      + "difference).",
    object: "Frame-to-frame shake of the landmarks' own tracks (RMS second difference).",
  } },
  track_jitter_px: { label: "Track shake", unit: "px/frame²", explain:
    "Frame-to-frame shake of the label's own track, with no reference: random clicks leap, "
    + "real tracks move smoothly." },
  track_jitter_ratio: { label: "Shake against other views", unit: "×", explain:
    "The track's own shake divided by that of the other views' tracks of the same clip." },
  jump_fraction: { label: "Jumps", unit: "%", explain:
    "Share of frame-to-frame steps where a landmark leaps far beyond the object's motion." },
  max_step_ratio: { label: "Largest step", unit: "×", explain:
    "The largest frame-to-frame step of a landmark, in multiples of its typical step." },
  static_fraction: { label: "Still frames", unit: "%", explain:
    "Share of frame-to-frame steps in which no point moves at all." },
  completeness: { label: "Completeness", unit: "%", explain:
    "Share of the points placed or marked occluded in every frame." },
  visible_fraction: { label: "Marked visible", unit: "%", explain:
    "Share of the points the worker marked visible." },
  scored_fraction: { label: "Judged", unit: "%", explain:
    "Share of the points that could be compared (at least two other views fix them)." },
  decided_fraction: { label: "Worker's own positions", unit: "%", explain:
    "Share of the shown points the worker placed, edited or tracked; the rest are "
    + "suggestions from the other views kept unchanged, which are never judged." },
  own_keyframes: { label: "Worker's own keyframes", unit: "", explain:
    "Keyframes the worker placed, tracked from its own, moved or marked hidden; none means "
    + "every value sent is a suggestion from the other views kept unchanged." },
  checks_accepted: { label: "Check suggestions kept", unit: "", explain:
    "Suggestions shown 15 px off the point on purpose that the worker accepted unchanged: "
    + "a worker who looks drags each one back." },
  checks_corrected: { label: "Check suggestions corrected", unit: "", explain:
    "Suggestions shown 15 px off the point on purpose that the worker moved back onto it." },
  working_time_s: { label: "Working time", unit: "s", explain:
    "Time the worker spent on the task." },
  solve_run: { label: "Solve run", unit: "", explain:
    "The 3D solve whose object poses the landmarks were checked against (none: the object's "
    + "pose given at import, for an object nobody moves)." },
};

/**
 * The metric's value with its unit.
 * @param {number|null|undefined} value
 * @param {string} unit
 */
function formatted(value, unit) {
  if (!isNumber(value)) return NONE;
  switch (unit) {
    case "px": return `${value.toFixed(1)} px`;
    case "mm": return `${value.toFixed(1)} mm`;
    case "%": return `${(value * 100).toFixed(1)}%`;
    case "s": return `${Math.round(value)} s`;
    case "px/frame²": return `${value.toFixed(1)} px/frame²`;
    case "×": return `${value.toFixed(2)}×`;
    default: return Number.isInteger(value) ? String(value) : value.toFixed(2);
  }
}

/**
 * A readable version of an unknown key: "foo_bar_px" -> "Foo bar", unit from its suffix.
 * @param {string} name
 * @returns {MetricInfo}
 */
function guessed(name) {
  const suffixes = /** @type {const} */ ([["_px", "px"], ["_mm", "mm"], ["_fraction", "%"],
    ["_s", "s"]]);
  for (const [suffix, unit] of suffixes) {
    if (name.endsWith(suffix) && name.length > suffix.length) {
      return { label: sentenceCase(name.slice(0, -suffix.length)), unit, explain: "" };
    }
  }
  return { label: sentenceCase(name), unit: "", explain: "" };
}

/** @param {string} key */
function sentenceCase(key) {
  const words = key.split("_").filter(Boolean).join(" ");
  return words ? words[0].toUpperCase() + words.slice(1) : key;
}

/**
 * What the report was judged against: gold labels, the other views (hands) or the object.
 * @param {{method?: string, target_key?: string}} report
 * @returns {Basis}
 */
export function basisOf(report) {
  if (report.method === "gold") return "gold";
  return String(report.target_key || "").startsWith("object:") ? "object" : "hand";
}

/**
 * The one-line explanation of a metric for a basis.
 * @param {MetricInfo} info
 * @param {Basis} basis
 */
function explanation(info, basis) {
  if (typeof info.explain === "string") return info.explain;
  return info.explain[basis] ?? info.explain.any ?? info.explain.hand ?? "";
}

/**
 * The limits a metric was held to and whether the value crossed one of them.
 * @param {string} name
 * @param {number|null|undefined} value
 * @param {string} unit
 * @param {Record<string, unknown>} thresholds  the report's, "<metric>.<level>_<above|below>"
 * @returns {{threshold: string|null, over: boolean}}
 */
export function thresholdOf(name, value, unit, thresholds) {
  const parts = [];
  let over = false;
  for (const level of ["review", "reject"]) {
    const sides = [];
    for (const side of ["below", "above"]) {
      const limit = thresholds[`${name}.${level}_${side}`];
      if (typeof limit !== "number" || !Number.isFinite(limit)) continue;
      sides.push(`${side} ${formatted(limit, unit)}`);
      if (typeof value === "number" && Number.isFinite(value)
        && (side === "above" ? value > limit : value < limit)) over = true;
    }
    if (sides.length) parts.push(`${level} ${sides.join(" or ")}`);
  }
  return { threshold: parts.length ? parts.join("; ") : null, over };
}

/**
 * Every metric of a QC report as a readable row: known metrics in a fixed order (most telling
 * first), then any others under a readable version of their key.
 * @param {{metrics?: Record<string, unknown>, thresholds?: Record<string, unknown>,
 *   method?: string, target_key?: string}} report
 * @returns {MetricRow[]}
 */
export function metricRows(report) {
  const metrics = report.metrics || {};
  const thresholds = report.thresholds || {};
  const basis = basisOf(report);
  const known = Object.keys(METRICS).filter((name) => name in metrics);
  const others = Object.keys(metrics).filter((name) => !(name in METRICS)).sort();
  return [...known, ...others].map((name) => {
    const info = METRICS[name] ?? guessed(name);
    const raw = metrics[name];
    const value = typeof raw === "number" ? raw : null;
    return {
      name, label: info.label, unit: info.unit, explain: explanation(info, basis),
      value: raw === null || raw === undefined || typeof raw === "number"
        ? formatted(value, info.unit) : String(raw),
      ...thresholdOf(name, value, info.unit, thresholds),
    };
  });
}

/**
 * Write a report's metric rows into a <dl>: per metric a <dt> with its name (the explanation
 * as its tooltip) and a <dd> with the value, the threshold in brackets, the explanation below,
 * data-metric = the key and data-over = "true" (and a "⚠" before the value, "crossed:" before
 * the threshold) where the value crossed it. Classes for a style sheet: dd.metric(.over),
 * .metric-threshold, .metric-explain.
 * @param {HTMLElement} dl
 * @param {Parameters<typeof metricRows>[0]} report
 * @returns {MetricRow[]} the rows written
 */
export function renderMetricList(dl, report) {
  const doc = dl.ownerDocument;
  const rows = metricRows(report);
  const nodes = rows.flatMap((row) => {
    const dt = doc.createElement("dt");
    dt.textContent = row.label;
    dt.title = row.explain || row.name;
    dt.setAttribute("data-metric", row.name);
    const dd = doc.createElement("dd");
    dd.setAttribute("data-metric", row.name);
    dd.setAttribute("data-over", String(row.over));
    dd.className = row.over ? "metric over" : "metric";
    const value = doc.createElement("strong");
    // Marked in the text too, so a crossed limit shows without any style sheet.
    value.textContent = row.over ? `⚠ ${row.value}` : row.value;
    dd.append(value);
    if (row.threshold) {
      const limit = doc.createElement("span");
      limit.className = "metric-threshold";
      limit.textContent = ` (${row.over ? "crossed: " : ""}${row.threshold})`;
      dd.append(limit);
    }
    if (row.explain) {
      const line = doc.createElement("small");
      line.className = "metric-explain";
      line.textContent = row.explain;
      dd.append(doc.createElement("br"), line);
    }
    return [dt, dd];
  });
  dl.replaceChildren(...nodes);
  return rows;
}
