/**
 * Rig health on the sequence page: each camera's time offset, pose correction and depth
 * scale/shift estimated from the accepted labels, the cameras that are off, and the actions
 * to estimate again, adopt the refined calibration (re-solving with it) or go back to the
 * imported one.
 */

import { $, el } from "../common/dom.js";
import { rigHandLines, rigRows, rigSummary } from "./core/rig-format.js";


/** @type {{ api: any, fail: (err: unknown) => void, sequence: number|null, status: any }} */
const state = { api: null, fail: () => {}, sequence: null, status: null };

function render() {
  const status = state.status;
  $("rig-summary").textContent = rigSummary(status);
  const report = status.report;
  $("rig-table").hidden = !report;
  $("rig-rows").replaceChildren(...(report ? rigRows(report) : []).map((row) =>
    el("tr", { class: row.faulty ? "rig-faulty" : "" },
      row.cells.map((text, i) => el("td", i > 0 && i < 7 ? { class: "num" } : {}, [text])))));
  const hands = report ? rigHandLines(report) : [];
  $("rig-hands").hidden = hands.length === 0;
  $("rig-hands").replaceChildren(...hands.map((line) =>
    el("li", { class: line.faulty ? "rig-faulty" : "" }, [line.text])));
  const adopt = /** @type {HTMLButtonElement} */ ($("rig-adopt"));
  adopt.hidden = !report || report.version === status.version_in_use;
  if (report) adopt.textContent = `Adopt version ${report.version} and re-solve`;
  $("rig-imported").hidden = status.version_in_use === 0;
}

/** @param {number} sequenceId */
export async function showRigHealth(sequenceId) {
  state.sequence = sequenceId;
  try {
    state.status = await state.api.rigHealth(sequenceId);
    render();
  } catch (err) {
    state.fail(err);
  }
}

/** @param {number} version */
async function adopt(version) {
  if (state.sequence === null) return;
  const result = await state.api.adoptCalibration(state.sequence, version);
  $("rig-result").textContent = `Version ${result.version_in_use} in use; solve: ${result.solve}`;
  $("rig-result").hidden = false;
  await showRigHealth(state.sequence);
}

/** @param {any} api @param {(err: unknown) => void} fail */
export function initRig(api, fail) {
  Object.assign(state, { api, fail });
  $("rig-estimate").addEventListener("click", async () => {
    if (state.sequence === null) return;
    try {
      state.status = await api.estimateRig(state.sequence);
      render();
    } catch (err) { fail(err); }
  });
  $("rig-adopt").addEventListener("click", () => {
    adopt(state.status.report.version).catch(fail);
  });
  $("rig-imported").addEventListener("click", () => { adopt(0).catch(fail); });
}
