/**
 * Solve tools of the sequence page: re-run the solve with other settings (optimiser and any
 * solver setting, starting from a run's own), and compare two done runs frame by frame (hand
 * joints in mm, each object's pose in mm and degrees) as a chart and a table of the largest
 * differences.
 */

import { $, el } from "../common/dom.js";
import { errorText, showNotice } from "../common/notice.js";
import { differenceChart } from "./solve-charts.js";
import { parseSettings } from "./core/solve-core.js";

const select = (/** @type {string} */ id) => /** @type {HTMLSelectElement} */ ($(id));
/** How often the runs are read again while one is queued or running, ms. */
const POLL_MS = 2000;

/**
 * @typedef {{ openOverlay: (run: number, frame?: number) => Promise<void>,
 *   reload: () => Promise<void> }} Hooks
 */
const tools = {
  api: /** @type {import("./api.js").AdminApi} */ (/** @type {any} */ (null)),
  fail: /** @type {(err: unknown) => void} */ (() => {}),
  hooks: /** @type {Hooks} */ (/** @type {any} */ (null)),
  /** @type {any[]} */ runs: [],
  /** Settings and their kinds per optimiser (GET /api/solve-settings). */
  /** @type {Map<string, {params: Record<string, any>, kinds: Record<string, string>}>} */
  defaults: new Map(),
  /** @type {any} */ base: null,
  /** @type {ReturnType<typeof setTimeout>|null} */ poll: null,
};

/** Counts re-run form fills: a fill that is no longer the newest draws nothing. */
let fills = 0;

/** @param {string} optimiser */
async function defaultsOf(optimiser) {
  if (!tools.defaults.has(optimiser)) {
    tools.defaults.set(optimiser, await tools.api.request(
      "GET", `/solve-settings?optimiser=${encodeURIComponent(optimiser)}`));
  }
  return /** @type {{params: Record<string, any>, kinds: Record<string, string>}} */ (
    tools.defaults.get(optimiser));
}

/**
 * Fill the re-run form from ``run``'s settings (null: the defaults) for ``optimiser`` (by
 * default the run's own).
 * @param {any} run @param {string} [optimiser]
 */
async function fillRerun(run, optimiser) {
  tools.base = run;
  const chosen = optimiser || (run ? run.optimiser : select("rerun-optimiser").value);
  select("rerun-optimiser").value = chosen;
  // Only the newest fill draws the form: an older one whose settings arrive later would
  // replace what the admin has typed since.
  const request = ++fills;
  const { params, kinds } = await defaultsOf(chosen);
  if (request !== fills) return;
  const own = run ? run.params || {} : {};
  $("rerun-base").textContent = run ? `starting from run #${run.id}'s settings` : "defaults";
  $("rerun-settings").replaceChildren(...Object.keys(params).map((name) => {
    const value = name in own ? own[name] : params[name];
    const field = kinds[name] === "bool"
      ? el("input", { type: "checkbox", name, ...(value ? { checked: "" } : {}) })
      : el("input", { type: "number", name, value: String(value),
        step: kinds[name] === "int" ? "1" : "any" });
    const changed = value !== params[name];
    return el("label", { class: changed ? "changed" : "" }, [name, field]);
  }));
  $("rerun-settings").dataset.optimiser = chosen;
}

/** @param {SubmitEvent} event */
async function submitRerun(event) {
  event.preventDefault();
  const status = $("rerun-status");
  const optimiser = select("rerun-optimiser").value;
  try {
    const { params, kinds } = await defaultsOf(optimiser);
    /** @type {Record<string, string|boolean>} */
    const edited = {};
    for (const field of $("rerun-settings").querySelectorAll("input")) {
      edited[field.name] = field.type === "checkbox" ? field.checked : field.value;
    }
    const parsed = parseSettings(kinds, edited);
    const changed = Object.fromEntries(Object.entries(parsed).filter(
      ([name, value]) => value !== params[name]));
    const sequence = Number($("solve-section").dataset.sequence);
    const run = await tools.api.request("POST", `/sequences/${sequence}/solve`,
      { optimiser, params: changed });
    const names = Object.keys(changed);
    showNotice(status, `Run #${run.id} is ${run.status} (${optimiser}` + (names.length
      ? `; ${names.map((n) => `${n} ${changed[n]}`).join(", ")})` : "; default settings)"));
    await tools.hooks.reload();
  } catch (err) {
    showNotice(status, errorText(err), "error");
  }
}

/** Compare the two chosen runs. */
async function compare() {
  const a = Number(select("compare-a").value), b = Number(select("compare-b").value);
  const result = $("compare-result");
  if (!a || !b) return;
  const diff = await tools.api.request("GET", `/solve-runs/${a}/compare/${b}`);
  const series = [{ name: "hand joints (mean)", values: diff.hand_mm },
    ...diff.objects.map((/** @type {any} */ o) => ({ name: `${o.name} (ADD)`, values: o.add_mm }))];
  $("compare-chart").replaceChildren(differenceChart(series, "mm"));
  const rotations = diff.objects.map((/** @type {any} */ o) => ({ name: `${o.name}`,
    values: o.rotation_deg }));
  $("compare-rotation").replaceChildren(rotations.length ? differenceChart(rotations, "deg") : "");
  $("compare-summary").textContent = `Run #${b} against run #${a}: hand joints `
    + (diff.hand_mean_mm === null ? "not solved in both" : `${diff.hand_mean_mm.toFixed(1)} mm apart on average`)
    + diff.objects.map((/** @type {any} */ o) => {
      const add = Math.max(0, ...o.add_mm.filter((/** @type {any} */ v) => v !== null));
      const deg = Math.max(0, ...o.rotation_deg.filter((/** @type {any} */ v) => v !== null));
      return `; ${o.name} up to ${add.toFixed(1)} mm, ${deg.toFixed(1)}°`;
    }).join("");
  $("compare-rows").replaceChildren(...diff.largest.map((/** @type {any} */ row) =>
    el("tr", {}, [
      el("td", { class: "num" }, [el("button", { type: "button", "data-frame": String(row.frame),
        "data-run": String(a), title: `show frame ${row.frame} of run #${a}` }, [String(row.frame)])]),
      el("td", {}, [row.target]),
      el("td", { class: "num" }, [row.mm.toFixed(2)]),
      el("td", { class: "num" }, [row.deg === null ? "–" : row.deg.toFixed(2)]),
    ])));
  result.dataset.pair = `${a}-${b}`;
  result.hidden = false;
}

/** Poll the runs while one is on its way, so its status and the compare lists follow. */
function schedulePoll() {
  if (tools.poll !== null) clearTimeout(tools.poll);
  tools.poll = null;
  if (!tools.runs.some((r) => r.status === "queued" || r.status === "running")) return;
  tools.poll = setTimeout(() => {
    tools.poll = null;
    if (!$("sequence-view").hidden) tools.hooks.reload().catch(tools.fail);
  }, POLL_MS);
}

/**
 * The runs of the sequence shown: compare choices (done runs; newest two preselected),
 * and the re-run form from the current run when the sequence changed.
 * @param {number} sequenceId @param {any[]} runs @param {boolean} changed
 */
export function showTools(sequenceId, runs, changed) {
  tools.runs = runs;
  $("solve-section").dataset.sequence = String(sequenceId);
  const done = runs.filter((r) => r.status === "done");
  for (const [id, pick] of [["compare-a", 1], ["compare-b", 0]]) {
    const list = select(String(id));
    const keep = changed ? "" : list.value;
    list.replaceChildren(...done.map((r) => el("option", { value: String(r.id) },
      [`#${r.id} · ${r.optimiser}${r.current ? " (current)" : ""}`])));
    const fallback = done[Math.min(Number(pick), done.length - 1)];
    list.value = done.some((r) => String(r.id) === keep) ? keep : String(fallback?.id ?? "");
  }
  /** @type {HTMLButtonElement} */ ($("compare-runs")).disabled = done.length < 1;
  $("solve-compare").hidden = done.length < 1;
  if (changed) {
    $("compare-result").hidden = true;
    $("rerun-status").hidden = true;
    fillRerun(runs.find((r) => r.current) || null).catch(tools.fail);
  }
  schedulePoll();
}

/**
 * @param {import("./api.js").AdminApi} api @param {(err: unknown) => void} fail
 * @param {Hooks} hooks
 */
export function initTools(api, fail, hooks) {
  Object.assign(tools, { api, fail, hooks });
  $("rerun-form").addEventListener("submit", (e) => submitRerun(/** @type {SubmitEvent} */ (e)));
  $("rerun-optimiser").addEventListener("change", () =>
    fillRerun(tools.base, select("rerun-optimiser").value).catch(fail));
  // A setting that differs from the default is marked as it is edited.
  $("rerun-settings").addEventListener("input", async (e) => {
    const field = /** @type {HTMLInputElement} */ (e.target);
    const { params } = await defaultsOf(select("rerun-optimiser").value);
    const value = field.type === "checkbox" ? field.checked : Number(field.value);
    field.parentElement?.classList.toggle("changed", value !== params[field.name]);
  });
  $("run-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-rerun]");
    if (!button) return;
    const run = tools.runs.find((r) => String(r.id) === button.getAttribute("data-rerun"));
    /** @type {HTMLDetailsElement} */ ($("solve-rerun")).open = true;
    fillRerun(run || null).then(() => $("solve-rerun").scrollIntoView({ block: "nearest" }))
      .catch(fail);
  });
  $("compare-runs").addEventListener("click", () => {
    showNotice($("compare-error"), "");
    compare().catch((err) =>
      showNotice($("compare-error"), errorText(err), "error"));
  });
  $("compare-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-frame]");
    if (!button) return;
    hooks.openOverlay(Number(button.getAttribute("data-run")),
      Number(button.getAttribute("data-frame"))).catch(fail);
    $("overlay").scrollIntoView({ block: "start" });
  });
}
