/**
 * The Costs page's "per labelled 3D frame" tables: one per sequence, a row per target (hand,
 * objects) and the total, from GET /api/frame-costs. A thin renderer over core/cost-format.js.
 */

import { el } from "../common/dom.js";
import { FRAME_COST_COLUMNS, frameCostCells, targetName } from "./core/cost-format.js";

/** @param {any} line @param {string} name @param {boolean} total */
function row(line, name, total) {
  return el("tr", { "data-target": line.target_key, class: total ? "total" : "" },
    frameCostCells(line, name).map((text, i) => el(i ? "td" : "th",
      i ? { class: "num" } : { scope: "row" }, [text])));
}

/**
 * @param {HTMLElement} at  where the tables go
 * @param {any[]} sequences  GET /api/frame-costs
 */
export function renderFrameCosts(at, sequences) {
  if (!sequences.length) {
    at.replaceChildren(el("p", { class: "muted" }, ["No sequences yet."]));
    return;
  }
  at.replaceChildren(...sequences.map((s) => el("div", {
    class: "table-box frame-costs", "data-sequence": String(s.sequence_id),
  }, [el("table", { class: "list" }, [
    el("caption", {}, [el("a", { href: `#/sequences/${s.sequence_id}` }, [s.name]),
      el("span", { class: "muted" }, [s.solve_run_id
        ? ` · 3D frames from solve run ${s.solve_run_id}` : " · not solved yet: no 3D frame"])]),
    el("thead", {}, [el("tr", {}, FRAME_COST_COLUMNS.map(([, title], i) => el("th",
      i ? { class: "num", scope: "col" } : { scope: "col" }, [title])))]),
    el("tbody", {}, s.targets.map((/** @type {any} */ t) => row(t, t.label || targetName(t.target_key),
      false))),
    el("tfoot", {}, [row(s.total, "All targets", true)]),
  ])])));
}
