/**
 * Solve review on the sequence page: the runs table, and a done run's overlays played frame
 * by frame per view (solid, blended or wireframe meshes), the frame's residual chart beside
 * them and the frames that need a look marked on the slider. Re-runs and comparisons live in
 * solve-tools.js.
 */

import { $, el } from "../common/dom.js";
import { when } from "./core/format.js";
import { residualChart } from "./solve-charts.js";
import { LatestLoader, overlayPath, stepFrame, tickPercent } from "./core/solve-core.js";
import { initTools, showTools } from "./solve-tools.js";

const input = (/** @type {string} */ id) => /** @type {HTMLInputElement} */ ($(id));
/** Pause between frames while playing, ms; the next frame also waits for the last to show. */
const PLAY_MS = 350;

/**
 * @typedef {{ api: import("./api.js").AdminApi, fail: (err: unknown) => void,
 *   sequence: number|null, runs: any[], serials: string[], run: any, frame: number,
 *   flagged: Map<number, any>, url: string|null, playing: boolean,
 *   loader: LatestLoader<[Blob, any]>|null }} SolveState
 */
/** @type {SolveState} */
const state = {
  api: /** @type {any} */ (null), fail: () => {}, sequence: null, runs: [], serials: [],
  run: null, frame: 0, flagged: new Map(), url: null, playing: false, loader: null,
};

/**
 * One row per run; a done run's "Review #N" opens its overlays, "Re-run…" fills the re-run form.
 * @param {HTMLTableSectionElement} body
 * @param {any[]} runs  GET /api/sequences/{id}/solve-runs
 */
export function renderRuns(body, runs) {
  body.replaceChildren(...runs.map((r) => el("tr", { "data-run": String(r.id) }, [
    el("td", { class: "num" }, [r.status === "done"
      ? el("button", { type: "button", "data-show-run": String(r.id),
        title: "review this run's overlays frame by frame" }, [`Review #${r.id}`])
      : `#${r.id}`]),
    el("td", {}, [el("span", { class: `status status-${r.status}` }, [r.status]),
      r.current ? el("span", { class: "muted" }, [" current"]) : ""]),
    el("td", {}, [r.optimiser]),
    el("td", { class: "num" }, [String(r.num_frames)]),
    el("td", { class: "num" }, [String(r.num_views)]),
    el("td", {}, [when(r.finished_at)]),
    el("td", { class: "error-text" }, [r.error || ""]),
    el("td", {}, [el("button", { type: "button", "data-rerun": String(r.id) }, ["Re-run…"])]),
  ])));
}

/**
 * The sequence page shows these runs: the table, the tools, and the overlay closed when its
 * run is gone.
 * @param {number} sequenceId @param {any[]} runs @param {string[]} serials
 */
export function showSolveRuns(sequenceId, runs, serials) {
  const changed = state.sequence !== sequenceId;
  Object.assign(state, { sequence: sequenceId, runs, serials });
  renderRuns(/** @type {HTMLTableSectionElement} */ ($("run-rows")), runs);
  $("no-runs").hidden = runs.length > 0;
  if (changed || !runs.some((r) => r.id === state.run?.id && r.status === "done")) hideOverlay();
  showTools(sequenceId, runs, changed);
}

/** The run shown, its frame and view, as the loader's key. */
function frameKey() {
  const alpha = /** @type {HTMLInputElement} */ ($("overlay-alpha"));
  return JSON.stringify({
    run: state.run.id, frame: state.frame, view: /** @type {HTMLSelectElement} */ (
      $("overlay-view")).value, style: /** @type {HTMLSelectElement} */ ($("overlay-style")).value,
    alpha: alpha.dataset.touched ? Number(alpha.value) : null,
  });
}

/** @param {string} key @returns {Promise<[Blob, any]>} */
async function loadFrame(key) {
  const { run, frame, view, style, alpha } = JSON.parse(key);
  const picture = state.api.send("GET", overlayPath(run, frame, view, style, alpha), undefined,
    "image/png").then((resp) => resp.blob());
  return Promise.all([picture, state.api.request("GET", `/solve-runs/${run}/frames/${frame}`)]);
}

/** @param {string} _key @param {[Blob, any]} reply */
function showFrame(_key, [blob, outputs]) {
  if ($("overlay").hidden) return;
  if (state.url) URL.revokeObjectURL(state.url);
  state.url = URL.createObjectURL(blob);
  /** @type {HTMLImageElement} */ ($("overlay-image")).src = state.url;
  $("solve-residuals").replaceChildren(residualChart(outputs.kpt_error_px, outputs.frame));
  $("solve-residual-title").textContent = `Reprojection error, frame ${outputs.frame}`;
  const flagged = state.flagged.get(outputs.frame);
  const status = $("solve-frame-status");
  const objects = outputs.objects.map((/** @type {any} */ o) =>
    `${o.name} ${o.pose ? `confidence ${o.confidence.toFixed(2)}` : "not solved"}`);
  status.textContent = [outputs.labelled ? "hand solved" : `hand not solved: ${outputs.reason || "–"}`,
    ...objects].join(" · ");
  status.classList.toggle("flagged", Boolean(flagged));
  status.title = flagged ? flagged.reasons.join("\n") : "";
}

/** Show frame ``frame`` of the run (the slider, label and ticks follow). @param {number} frame */
function setFrame(frame) {
  if (!state.run) return Promise.resolve();
  state.frame = stepFrame(frame, 0, state.run.num_frames);
  input("overlay-frame").value = String(state.frame);
  $("solve-frame-label").textContent = `Frame ${state.frame} of ${state.run.num_frames - 1}`;
  for (const tick of $("solve-ticks").children) {
    tick.classList.toggle("current", /** @type {HTMLElement} */ (tick).dataset.frame
      === String(state.frame));
  }
  return /** @type {LatestLoader<[Blob, any]>} */ (state.loader).request(frameKey());
}

/** @param {any} timeline  GET /api/solve-runs/{id}/timeline */
function renderFlagged(timeline) {
  state.flagged = new Map(timeline.flagged.map((/** @type {any} */ f) => [f.frame, f]));
  const count = state.run.num_frames;
  $("solve-ticks").replaceChildren(...timeline.flagged.map((/** @type {any} */ f) => el("button", {
    type: "button", class: "tick", "data-frame": String(f.frame),
    style: `left: ${tickPercent(f.frame, count).toFixed(3)}%`,
    title: `frame ${f.frame}: ${f.reasons.join("; ")}`,
    "aria-label": `flagged frame ${f.frame}`,
  })));
  $("solve-flagged").replaceChildren(...timeline.flagged.map((/** @type {any} */ f) =>
    el("li", {}, [el("button", { type: "button", "data-frame": String(f.frame) },
      [`Frame ${f.frame}`]), el("span", {}, [` ${f.reasons.join("; ")}`])])));
  $("solve-flagged-count").textContent = timeline.flagged.length
    ? `${timeline.flagged.length} of ${count} frames` : "none";
}

/**
 * Open a done run's overlays at ``frame`` (0 by default).
 * @param {number} runId @param {number} [frame]
 */
export async function openOverlay(runId, frame = 0) {
  const run = state.runs.find((r) => r.id === runId);
  if (!run) return;
  pause();
  const same = state.run?.id === run.id && !$("overlay").hidden;
  state.run = run;
  const overlay = $("overlay");
  overlay.dataset.run = String(run.id);
  $("overlay-title").textContent = `Run #${run.id} · ${run.optimiser}`;
  input("overlay-frame").max = String(Math.max(run.num_frames - 1, 0));
  if (!same) {
    const views = run.num_views, serials = state.serials;
    const select = /** @type {HTMLSelectElement} */ ($("overlay-view"));
    select.replaceChildren(...Array.from({ length: views }, (_, i) => el("option",
      { value: String(i) }, [serials.length === views ? `${i} · ${serials[i]}` : String(i)])));
    state.flagged = new Map();
    $("solve-ticks").replaceChildren();
    $("solve-flagged").replaceChildren();
  }
  overlay.hidden = false;
  const shown = setFrame(frame);
  if (!same) {
    const timeline = await state.api.request("GET", `/solve-runs/${run.id}/timeline`);
    if (state.run?.id === run.id) renderFlagged(timeline);
    setFrame(state.frame);
  }
  await shown;
}

export function hideOverlay() {
  pause();
  $("overlay").hidden = true;
  delete $("overlay").dataset.run;
  state.run = null;
  state.loader?.cancel();
  if (state.url) URL.revokeObjectURL(state.url);
  state.url = null;
  /** @type {HTMLImageElement} */ ($("overlay-image")).removeAttribute("src");
}

function pause() {
  state.playing = false;
  $("solve-play").textContent = "Play";
  $("solve-play").setAttribute("aria-pressed", "false");
}

async function play() {
  if (!state.run) return;
  state.playing = true;
  $("solve-play").textContent = "Pause";
  $("solve-play").setAttribute("aria-pressed", "true");
  while (state.playing && state.run) {
    if ($("sequence-view").hidden) {  // the page moved on: stop fetching frames nobody sees
      pause();
      break;
    }
    await setFrame(stepFrame(state.frame, 1, state.run.num_frames, true));
    await new Promise((resolve) => setTimeout(resolve, PLAY_MS));
  }
}

/** ←/→ step, space plays or pauses, while the overlay panel has the focus. @param {KeyboardEvent} e */
function onKey(e) {
  const target = /** @type {HTMLElement} */ (e.target);
  if (target.matches("select, textarea, input:not([type=range])")) return;
  if (e.key === "ArrowLeft" || e.key === "ArrowRight") {
    e.preventDefault();  // the slider would step too
    pause();
    setFrame(stepFrame(state.frame, e.key === "ArrowLeft" ? -1 : 1, state.run?.num_frames ?? 0));
  } else if (e.key === " " && target.tagName !== "BUTTON") {
    e.preventDefault();
    if (state.playing) pause(); else play();
  }
}

/**
 * Wire the section's controls.
 * @param {import("./api.js").AdminApi} api @param {(err: unknown) => void} fail
 */
export function initSolve(api, fail) {
  state.api = api;
  state.fail = fail;
  state.loader = new LatestLoader(loadFrame, showFrame, fail);
  $("run-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-show-run]");
    if (button) openOverlay(Number(/** @type {HTMLElement} */ (button).dataset.showRun)).catch(fail);
  });
  const frameButtons = (/** @type {Event} */ e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-frame]");
    if (!button) return;
    pause();
    setFrame(Number(/** @type {HTMLElement} */ (button).dataset.frame));
  };
  $("solve-ticks").addEventListener("click", frameButtons);
  $("solve-flagged").addEventListener("click", frameButtons);
  input("overlay-frame").addEventListener("input", () => {
    pause();
    setFrame(Number(input("overlay-frame").value));
  });
  $("solve-prev").addEventListener("click", () => { pause(); setFrame(state.frame - 1); });
  $("solve-next").addEventListener("click", () => { pause(); setFrame(state.frame + 1); });
  $("solve-play").addEventListener("click", () => (state.playing ? pause() : play().catch(fail)));
  $("overlay-view").addEventListener("change", () => setFrame(state.frame));
  input("overlay-alpha").addEventListener("input", () => {
    input("overlay-alpha").dataset.touched = "1";
    $("overlay-alpha-value").textContent = `${Math.round(Number(input("overlay-alpha").value) * 100)}%`;
    setFrame(state.frame);
  });
  $("overlay-style").addEventListener("change", () => {
    delete input("overlay-alpha").dataset.touched;  // each style starts at its own opacity
    const style = /** @type {HTMLSelectElement} */ ($("overlay-style")).value;
    const alpha = { solid: 0.85, blend: 0.5, wireframe: 1 }[style] ?? 1;
    input("overlay-alpha").value = String(alpha);
    $("overlay-alpha-value").textContent = `${Math.round(alpha * 100)}%`;
    setFrame(state.frame);
  });
  $("overlay").addEventListener("keydown", onKey);
  $("overlay-close").addEventListener("click", hideOverlay);
  initTools(api, fail, { openOverlay, reload: reloadRuns });
}

/** Fetch the runs of the sequence shown again (after a re-run, while runs are busy). */
async function reloadRuns() {
  if (state.sequence === null) return;
  const sequence = state.sequence;
  const runs = await state.api.solveRuns(sequence);
  if (state.sequence === sequence) showSolveRuns(sequence, runs, state.serials);
}
