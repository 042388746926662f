/** Thin renderers of the review page: they build DOM from API replies, nothing more. */

import { el, svg } from "../common/dom.js";
import { dollars, duration } from "../common/format.js";
import { metricRows } from "./metrics.js";
import {
  COST_COLUMNS, awaitsAdmin, barLayout, canRetry, costCells, jobOutcome, percent,
  px, when,
} from "./core/format.js";
import {
  jobDetail, progressLine, progressSegments, solveLine, sparkline, taskCounts,
} from "./core/project-format.js";

/** @param {string} text @param {string} [kind] */
export function badge(text, kind = text) {
  return el("span", { class: `status status-${kind}` }, [text]);
}

/**
 * @param {HTMLTableSectionElement} body
 * @param {any[]} sequences   GET /api/sequences
 * @param {Map<number, any>} [progress]  GET /api/progress by sequence id
 */
export function renderSequences(body, sequences, progress = new Map()) {
  body.replaceChildren(...sequences.map((s) => el("tr", { "data-sequence": String(s.id) }, [
    el("td", {}, [el("a", { href: `#/sequences/${s.id}` }, [`${s.subject}/${s.name}`]),
      el("span", { class: "muted" }, [` #${s.id}`]),
      el("div", { class: "muted small", title: "imported" }, [when(s.created_at)])]),
    el("td", { class: "num" }, [String(s.num_frames),
      el("div", { class: "muted small" }, [`${s.fps} fps`])]),
    el("td", { class: "num" }, [String(s.cameras.length)]),
    el("td", { class: "targets" }, [
      s.hands.map((/** @type {any} */ h) => `${h.side} hand`).join(", ") || "no hand",
      el("div", { class: "muted small" }, [
        s.objects.map((/** @type {any} */ o) => o.name).join(", ") || "no object"])]),
    el("td", { class: "progress-cell" }, progress.has(s.id)
      ? [progressSummary(progress.get(s.id))] : [el("span", { class: "muted" }, ["–"])]),
    el("td", {}, [el("button", { type: "button", "data-export": String(s.id) }, ["Export"])]),
  ])));
}

/**
 * A compact progress summary: the sequence's state, a bar of its tasks per state, one line.
 * @param {any} p   GET /api/sequences/{id}/progress
 */
export function progressSummary(p) {
  const bar = el("span", { class: "mini-bar", "aria-hidden": "true" },
    progressSegments(p.counts).map((g) => el("span", {
      class: `seg state-${g.state.replace(" ", "-")}`, style: `width:${g.percent.toFixed(1)}%`,
      title: `${g.count} ${g.state}`,
    })));
  return el("div", { class: "progress-summary", "data-state": p.state }, [
    badge(p.state, p.state.replace(" ", "-")), bar,
    el("div", { class: "muted small" }, [`${progressLine(p)}; ${solveLine(p)}`]),
  ]);
}

// A task the adaptive publishing policy holds back (backend/crowd/adaptive.py).
const HELD = "published only if a solve is unsure without this view";

/**
 * The view x target grid of a sequence's tasks: one cell per task with its state, HITs and
 * assignments; views down, targets across.
 * @param {HTMLTableElement} table
 * @param {any} p   GET /api/sequences/{id}/progress
 */
export function renderProgressGrid(table, p) {
  const cells = new Map(p.tasks.map((/** @type {any} */ t) => [`${t.serial} ${t.target_key}`, t]));
  const head = el("thead", {}, [el("tr", {}, [el("th", {}, ["View"]),
    ...p.targets.map((/** @type {string} */ t) => el("th", {}, [t]))])]);
  const rows = p.views.map((/** @type {string} */ serial) => el("tr", { "data-serial": serial }, [
    el("th", { scope: "row" }, [serial]),
    ...p.targets.map((/** @type {string} */ target) => {
      const t = cells.get(`${serial} ${target}`);
      if (!t) return el("td", { class: "cell none" }, ["–"]);
      const a = t.assignments;
      const why = t.held ? HELD : t.publish_reason;
      return el("td", {
        class: `cell state-${t.state.replace(" ", "-")}${t.held ? " held" : ""}`,
        "data-task": String(t.task_id), "data-target": target, "data-state": t.state,
        title: `task ${t.task_id}: ${t.hits} HITs (${t.hits_live} open); ${a.working} working, `
          + `${a.submitted} submitted, ${a.approved} approved, ${a.rejected} rejected`
          + (why ? `\n${why}` : ""),
      }, [el("span", { class: "cell-state" }, [t.held ? "held back" : t.state]),
        el("span", { class: "cell-counts" }, [taskCounts(t)]),
        why ? el("span", { class: "cell-reason" }, [why]) : ""]);
    }),
  ]));
  table.replaceChildren(head, el("tbody", {}, rows));
}

/**
 * One row per report; the row of ``selected`` is marked.
 * @param {HTMLTableSectionElement} body
 * @param {any[]} reports       already filtered and ordered
 * @param {number} sequenceId
 * @param {number|null} selected  assignment id
 */
export function renderReports(body, reports, sequenceId, selected) {
  body.replaceChildren(...reports.map((r) => {
    const row = el("tr", {
      "data-assignment": String(r.assignment_id), "data-outcome": r.outcome,
      class: [awaitsAdmin(r) ? "waiting" : "", r.assignment_id === selected ? "selected" : ""]
        .join(" ").trim(),
    }, [
      el("td", { class: "num" }, [el("a", {
        href: `#/sequences/${sequenceId}/reports/${r.assignment_id}`,
      }, [String(r.assignment_id)])]),
      el("td", {}, [r.target_key]),
      el("td", {}, [r.worker_id]),
      el("td", {}, [r.method]),
      el("td", {}, [badge(r.outcome), r.provisional ? el("span", { class: "muted" },
        [" provisional"]) : ""]),
      el("td", { class: "num" }, [String(r.views)]),
      // Object landmarks are measured on the solved object (anchored) where there is no
      // consensus of views.
      el("td", { class: "num" }, [px(r.metrics.median_error_px ?? r.metrics.anchored_median_px)]),
      el("td", { class: "num" }, [px(r.metrics.p90_error_px ?? r.metrics.anchored_p90_px)]),
      el("td", { class: "num" }, [percent(r.metrics.outlier_fraction)]),
      el("td", { class: "action-cell" }, [actionBadge(r),
        r.action_detail ? el("div", { class: "muted" }, [r.action_detail]) : ""]),
    ]);
    return row;
  }));
}

/** @param {any} report */
function actionBadge(report) {
  if (report.action) return badge(report.action, "action");
  if (awaitsAdmin(report)) return badge("waiting for you", "review");
  return el("span", { class: "muted" }, ["none"]);
}

/**
 * The facts of one report: outcome, reasons, every metric, the thresholds' source.
 * @param {HTMLElement} list  a <dl>
 * @param {any} report  GET /api/qc/reports/{assignment_id}
 */
export function renderFacts(list, report) {
  /** @type {[string, Node|string][]} */
  const facts = [
    ["Outcome", badge(report.outcome)],
    ["Worker", report.worker_id],
    ["Target", `${report.target_key} (task ${report.task_id})`],
    ["Method", `${report.method}, ${report.views} views`
      + (report.provisional ? ", provisional" : "")],
    ["Reasons", report.reasons.length ? report.reasons.join("; ") : "–"],
    ["Action", report.action ? `${report.action}${report.action_detail
      ? ` (${report.action_detail})` : ""}` : (report.action_detail || "none yet")],
  ];
  const plain = facts.flatMap(([name, value]) => [
    el("dt", {}, [name]), el("dd", { "data-fact": name }, [value])]);
  // Metrics under readable names, each with its unit, the limits it was held to and what it
  // measures (the key stays in data-fact; the explanation is the row's tooltip).
  const measured = metricRows(report).flatMap((row) => [
    el("dt", { title: row.explain || row.name }, [row.label]),
    el("dd", { "data-fact": row.name, title: row.explain || "",
      class: row.over ? "over" : "" }, [
      el("span", { class: "value" }, [row.over ? `\u26a0 ${row.value}` : row.value]),
      row.threshold ? el("span", { class: "muted" }, [` (${row.threshold})`]) : ""]),
  ]);
  list.replaceChildren(...plain, ...measured);
}

/**
 * A bar chart as SVG: one bar per value, its label and value in the bar's tooltip; unknown
 * values show as a small grey mark.
 * @param {(number|null)[]} values  px
 * @param {string[]} labels
 * @param {string} name   names the chart for tests and screen readers
 * @param {boolean} [labelBars]  write each label under its bar (few bars)
 */
export function barChart(values, labels, name, labelBars = false) {
  const layout = barLayout(values, labels, { width: 600, height: 140 });
  const bottom = labelBars ? 70 : 16;
  const root = svg("svg", {
    viewBox: `0 -14 ${layout.width} ${layout.height + 14 + bottom}`, role: "img",
    "aria-label": name, "data-chart": name, "data-max": layout.max,
  });
  root.append(svg("text", { x: 0, y: -3, class: "axis" }, [`max ${px(layout.max)}`]),
    svg("line", { x1: 0, x2: layout.width, y1: layout.height, y2: layout.height, class: "axis" }));
  for (const bar of layout.bars) {
    const missing = bar.value === null;
    root.append(svg("rect", {
      x: bar.x, y: missing ? layout.height - 2 : bar.y, width: bar.width,
      height: missing ? 2 : bar.height, class: missing ? "col missing" : "col",
      "data-label": bar.label, "data-value": missing ? "" : bar.value,
    }, [svg("title", {}, [`${bar.label}: ${px(bar.value)}`])]));
    if (labelBars) {
      const cx = bar.x + bar.width / 2, cy = layout.height + 6;
      root.append(svg("text", {
        x: cx, y: cy, class: "tick", transform: `rotate(60 ${cx} ${cy})`,
      }, [bar.label]));
    }
  }
  if (!labelBars) {
    root.append(svg("text", { x: 0, y: layout.height + 13, class: "tick" }, ["0"]),
      svg("text", { x: layout.width, y: layout.height + 13, class: "tick end" },
        [String(values.length - 1)]));
  }
  return root;
}

/**
 * @param {HTMLElement} list  a <ul>
 * @param {any[]} swaps
 */
export function renderSwaps(list, swaps) {
  list.replaceChildren(...(swaps.length
    ? swaps.map((s) => el("li", {}, [s.message || JSON.stringify(s),
      s.error_px !== undefined ? el("span", { class: "muted" },
        [` (${px(s.error_px)} as labelled, ${px(s.error_swapped_px)} exchanged)`]) : ""]))
    : [el("li", { class: "muted" }, ["none found"])]));
}

/**
 * A worker's quality over time: one mark per QC report by date, its height the report's
 * median error (higher is worse), its colour the outcome; unmeasured reports sit on the base.
 * @param {any[]} history   oldest first
 * @param {number} [width] @param {number} [height]
 */
export function qualitySparkline(history, width = 96, height = 28) {
  const { points, max } = sparkline(history, width, height);
  const root = svg("svg", { class: "spark", viewBox: `0 0 ${width} ${height}`, width, height,
    role: "img", "data-points": points.length, "data-max": max,
    "aria-label": `${points.length} QC reports, largest median error ${px(max)}` });
  root.append(svg("line", { class: "spark-base", x1: 0, x2: width, y1: height - 0.5,
    y2: height - 0.5 }));
  const measured = points.filter((p) => p.y !== null);
  if (measured.length > 1) {
    root.append(svg("polyline", { class: "spark-line",
      points: measured.map((p) => `${p.x.toFixed(1)},${(p.y ?? 0).toFixed(1)}`).join(" ") }));
  }
  for (const p of points) {
    root.append(svg("circle", { cx: p.x.toFixed(1), cy: (p.y ?? height - 3).toFixed(1), r: 2.5,
      class: `spark-dot ${p.outcome}`, "data-error": p.error ?? "", "data-outcome": p.outcome },
    [svg("title", {}, [`${when(p.at)}: ${p.outcome}, median ${px(p.error)}`])]));
  }
  return root;
}

/**
 * One row per worker; the row of ``selected`` is marked.
 * @param {HTMLTableSectionElement} body
 * @param {any[]} workers   GET /api/crowd/workers
 * @param {string|null} [selected]
 */
export function renderWorkers(body, workers, selected = null) {
  body.replaceChildren(...workers.map((w) => el("tr", {
    "data-worker": w.worker_id, class: w.worker_id === selected ? "selected" : "",
  }, [
    el("td", { class: "clip", title: w.worker_id }, [el("button", {
      type: "button", class: "link", "data-open-worker": w.worker_id }, [w.worker_id])]),
    el("td", {}, [qualitySparkline(w.history)]),
    el("td", { class: "num" }, [String(w.submitted)]),
    el("td", { class: "num", title: `${w.approved} approved, ${w.rejected} rejected` },
      [percent(w.approval_rate)]),
    el("td", { class: "num", title: `over ${w.scored} final QC reports` }, [percent(w.score)]),
    el("td", { class: "num" }, [px(w.median_error_px)]),
    el("td", { class: "num" }, [duration(w.median_working_time_s)]),
    el("td", { class: "num", title: `rewards ${dollars(w.earned_rewards)}, bonuses `
      + `${dollars(w.earned_bonuses)}` }, [dollars(w.earned)]),
    el("td", {}, [w.blocked ? badge("blocked", "reject") : "no"]),
  ])));
}

/**
 * A worker's page: their stats, quality over time, and their newest assignments (the ones
 * the marketplace confirmed can be chosen for a bonus).
 * @param {{facts: HTMLElement, chart: HTMLElement, assignments: HTMLElement,
 *          bonusFor: HTMLSelectElement}} at
 * @param {any} w   GET /api/crowd/workers/{id}
 */
export function renderWorkerDetail(at, w) {
  /** @type {[string, string][]} */
  const facts = [
    ["Submitted", `${w.submitted} (${w.approved} approved, ${w.rejected} rejected)`],
    ["Approval rate", percent(w.approval_rate)],
    ["QC score", `${percent(w.score)} over ${w.scored} final reports`],
    ["Median error", px(w.median_error_px)],
    ["Time per task", `${duration(w.median_working_time_s)} (median working time)`],
    ["Earned", `${dollars(w.earned)} (rewards ${dollars(w.earned_rewards)}, bonuses `
      + `${dollars(w.earned_bonuses)})`],
    ["Blocked", w.blocked ? `yes: ${w.block_reason || "no reason given"}` : "no"],
  ];
  at.facts.replaceChildren(...facts.flatMap(([name, value]) => [
    el("dt", {}, [name]), el("dd", { "data-fact": name }, [value])]));
  const errors = w.history.map((/** @type {any} */ p) => p.median_error_px)
    .filter((/** @type {unknown} */ e) => typeof e === "number");
  const reports = `${w.history.length} QC report${w.history.length === 1 ? "" : "s"}`;
  at.chart.replaceChildren(...(w.history.length ? [qualitySparkline(w.history, 420, 60),
    el("p", { class: "muted small", "data-caption": "quality" }, [errors.length
      ? `${reports} from ${when(w.history[0].at)} to ${when(w.history.at(-1).at)}; median `
        + `error ${px(Math.min(...errors))} to ${px(Math.max(...errors))} (higher is worse)`
      : `${reports}, none with a measured error yet (too few views to compare with)`])]
    : [el("p", { class: "muted" }, ["No QC reports yet."])]));
  at.assignments.replaceChildren(...w.assignments.map((/** @type {any} */ a) => el("tr", {
    "data-assignment": String(a.assignment_id) }, [
    el("td", { class: "num" }, [String(a.assignment_id)]),
    el("td", {}, [el("a", { href: `#/sequences/${a.sequence_id}` }, [a.sequence]),
      el("div", { class: "muted" }, [a.target_key])]),
    el("td", {}, [badge(a.status, a.status === "approved" ? "approve" : a.status === "rejected"
      ? "reject" : a.status), a.qc_outcome ? el("div", { class: "muted" },
      [`QC ${a.qc_outcome}, ${px(a.median_error_px)}`]) : ""]),
    el("td", { class: "num" }, [duration(a.working_time_s)]),
    el("td", { class: "num" }, [a.reward === null ? "–" : dollars(a.reward),
      Number(a.bonuses) > 0 ? el("div", { class: "muted" }, [`+ ${dollars(a.bonuses)} bonus`])
        : ""]),
  ])));
  const payable = w.assignments.filter((/** @type {any} */ a) => a.confirmed);
  at.bonusFor.replaceChildren(...payable.map((/** @type {any} */ a) => el("option", {
    value: String(a.assignment_id) }, [`#${a.assignment_id} · ${a.sequence} · ${a.target_key}`])));
}

/**
 * One row per job with its result or error in one line (the whole of it in the line's
 * tooltip, and in a row under it once expanded: data-expand = job id); failed and waiting
 * ones get a Retry button (data-retry = job id).
 * @param {HTMLTableSectionElement} body
 * @param {any[]} jobs   GET /api/jobs
 * @param {Set<number>} [expanded]  ids of the jobs shown whole
 */
export function renderJobs(body, jobs, expanded = new Set()) {
  body.replaceChildren(...jobs.flatMap((j) => {
    const outcome = jobOutcome(j);
    const open = expanded.has(j.id);
    const row = el("tr", { "data-job": String(j.id), "data-kind": j.kind, "data-status": j.status,
      class: open ? "expanded" : "" }, [
      el("td", { class: "num" }, [el("button", { type: "button", class: "link expand",
        "data-expand": String(j.id), "aria-expanded": String(open),
        title: open ? "hide the whole result" : "show the whole result" },
      [`${open ? "▾" : "▸"} ${j.id}`])]),
      el("td", { class: "clip", title: j.key }, [el("code", {}, [j.key])]),
      el("td", {}, [badge(j.status)]),
      el("td", { class: "num" }, [`${j.attempts} / ${j.max_attempts}`]),
      el("td", { class: "nowrap" }, [when(j.updated_at)]),
      el("td", { class: "job-outcome" }, [el("div", {
        class: `outcome-line ${outcome.tone}`.trim(), title: outcome.full,
        "data-outcome": outcome.line,
      }, [outcome.line])]),
      el("td", { class: "job-action" }, [canRetry(j)
        ? el("button", { type: "button", "data-retry": String(j.id) }, ["Retry"]) : ""]),
    ]);
    if (!open) return [row];
    return [row, el("tr", { class: "job-detail", "data-detail-of": String(j.id) }, [
      el("td", { colspan: "7" }, [
        el("div", { class: "muted" }, [`${j.kind} · created ${when(j.created_at)} · started `
          + `${when(j.started_at)} · finished ${when(j.finished_at)} · arguments `
          + JSON.stringify(j.args)]),
        el("pre", { class: `job-text ${j.error ? "error" : ""}`.trim() }, [jobDetail(j)]),
      ])])];
  }));
}

/**
 * The project's totals as stats, and one table row per sequence and per worker.
 * @param {{summary: HTMLElement, sequenceHead: HTMLElement, sequences: HTMLElement,
 *          workerHead: HTMLElement, workers: HTMLElement}} at
 * @param {any} costs   GET /api/crowd/costs
 */
export function renderCosts(at, costs) {
  const t = costs.total;
  at.summary.replaceChildren(
    el("div", { class: "stat", id: "cost-spent" }, [el("b", {}, [dollars(t.spent)]), " spent",
      el("div", { class: "muted" }, [`rewards ${dollars(t.spent_rewards)} · bonuses `
        + `${dollars(t.spent_bonuses)} · fees ${dollars(t.spent_fees)}`])]),
    el("div", { class: "stat", id: "cost-committed" }, [el("b", {}, [dollars(t.committed)]),
      " committed", el("div", { class: "muted" }, [`rewards ${dollars(t.committed_rewards)} · `
        + `bonuses ${dollars(t.committed_bonuses)} · fees ${dollars(t.committed_fees)}`])]),
  );
  const head = (/** @type {string} */ first) => el("tr", {}, [el("th", {}, [first]),
    ...COST_COLUMNS.map(([, title]) => el("th", { class: "num" }, [title]))]);
  at.sequenceHead.replaceChildren(head("Sequence"));
  at.workerHead.replaceChildren(head("Worker"));
  const rows = (/** @type {any[]} */ lines, /** @type {string} */ attr) => lines.map((line) =>
    el("tr", { [attr]: line.key }, costCells(line).map((text, i) => el("td",
      i ? { class: "num" } : {}, [i || attr !== "data-sequence" ? text
        : el("a", { href: `#/sequences/${line.key}`, title: `sequence #${line.key}` }, [text])]))));
  at.sequences.replaceChildren(...rows(costs.by_sequence, "data-sequence"));
  at.workers.replaceChildren(...rows(costs.by_worker, "data-worker"));
}
