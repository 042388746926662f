/** Thin renderers of the review page: they build DOM from API replies, nothing more. */

import {
  COST_COLUMNS, awaitsAdmin, barLayout, canRetry, costCells, dollars, jobOutcome, metric, percent,
  px, when,
} from "./format.js";

const SVG = "http://www.w3.org/2000/svg";

/**
 * @param {string} tag
 * @param {Record<string, string>} [attrs]
 * @param {(Node|string)[]} [children]
 */
export function el(tag, attrs = {}, children = []) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) node.setAttribute(name, value);
  node.append(...children);
  return node;
}

/**
 * @param {string} tag
 * @param {Record<string, string|number>} [attrs]
 * @param {(Node|string)[]} [children]
 */
function svg(tag, attrs = {}, children = []) {
  const node = document.createElementNS(SVG, tag);
  for (const [name, value] of Object.entries(attrs)) node.setAttribute(name, String(value));
  node.append(...children);
  return node;
}

/** @param {string} text @param {string} [kind] */
function badge(text, kind = text) {
  return el("span", { class: `status status-${kind}` }, [text]);
}

/**
 * @param {HTMLTableSectionElement} body
 * @param {any[]} sequences   GET /api/sequences
 */
export function renderSequences(body, sequences) {
  body.replaceChildren(...sequences.map((s) => el("tr", { "data-sequence": String(s.id) }, [
    el("td", {}, [el("a", { href: `#/sequences/${s.id}` }, [`${s.subject}/${s.name}`]),
      el("span", { class: "muted" }, [` #${s.id}`])]),
    el("td", { class: "num" }, [String(s.num_frames)]),
    el("td", { class: "num" }, [String(s.fps)]),
    el("td", { class: "num" }, [String(s.cameras.length)]),
    el("td", {}, [s.objects.map((/** @type {any} */ o) => o.name).join(", ") || "–"]),
    el("td", {}, [s.hands.map((/** @type {any} */ h) => h.side).join(", ") || "–"]),
    el("td", {}, [when(s.created_at)]),
    el("td", {}, [el("button", { type: "button", "data-export": String(s.id) }, ["Export"])]),
  ])));
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
      el("td", { class: "num" }, [px(r.metrics.median_error_px)]),
      el("td", { class: "num" }, [px(r.metrics.p90_error_px)]),
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
  for (const [name, value] of Object.entries(report.metrics)) {
    facts.push([name, metric(name, value)]);
  }
  list.replaceChildren(...facts.flatMap(([name, value]) => [
    el("dt", {}, [name]), el("dd", { "data-fact": name }, [value])]));
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
 * @param {HTMLTableSectionElement} body
 * @param {any[]} workers   GET /api/qc/workers
 */
export function renderWorkers(body, workers) {
  body.replaceChildren(...workers.map((w) => el("tr", { "data-worker": w.worker_id }, [
    el("td", {}, [w.worker_id]),
    el("td", { class: "num" }, [String(w.scored)]),
    el("td", { class: "num" }, [String(w.approved)]),
    el("td", { class: "num" }, [String(w.review)]),
    el("td", { class: "num" }, [String(w.rejected)]),
    el("td", { class: "num" }, [percent(w.score)]),
    el("td", {}, [w.blocked ? badge("blocked", "reject") : "no"]),
  ])));
}

/**
 * One row per job with its result or error in one line (the whole error in the line's
 * tooltip); failed and waiting ones get a Retry button (data-retry = job id).
 * @param {HTMLTableSectionElement} body
 * @param {any[]} jobs   GET /api/jobs
 */
export function renderJobs(body, jobs) {
  body.replaceChildren(...jobs.map((j) => {
    const outcome = jobOutcome(j);
    return el("tr", { "data-job": String(j.id), "data-kind": j.kind, "data-status": j.status }, [
      el("td", { class: "num" }, [String(j.id)]),
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
    el("tr", { [attr]: line.key }, costCells(line).map((text, i) =>
      el("td", i ? { class: "num" } : {}, [text]))));
  at.sequences.replaceChildren(...rows(costs.by_sequence, "data-sequence"));
  at.workers.replaceChildren(...rows(costs.by_worker, "data-worker"));
}

/**
 * @param {HTMLTableSectionElement} body
 * @param {any[]} runs   GET /api/sequences/{id}/solve-runs
 */
export function renderRuns(body, runs) {
  body.replaceChildren(...runs.map((r) => el("tr", { "data-run": String(r.id) }, [
    el("td", { class: "num" }, [r.status === "done"
      ? el("button", { type: "button", "data-show-run": String(r.id) }, [`#${r.id}`])
      : `#${r.id}`]),
    el("td", {}, [badge(r.status), r.current ? el("span", { class: "muted" }, [" current"]) : ""]),
    el("td", {}, [r.optimiser]),
    el("td", { class: "num" }, [String(r.num_frames)]),
    el("td", { class: "num" }, [String(r.num_views)]),
    el("td", {}, [when(r.finished_at)]),
    el("td", { class: "error-text" }, [r.error || ""]),
  ])));
}
