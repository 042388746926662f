/**
 * Each worker's record on the admin page (#/workers): their quality over time, assignments and
 * stats, with block, unblock and bonus, each asked about under the record and done only once
 * confirmed.
 */

import { $, el } from "../common/dom.js";
import { dollars } from "../common/format.js";
import { showFailure, showNotice } from "../common/notice.js";
import { ConfirmBox } from "./confirm.js";
import { workerName } from "./core/crowd-format.js";
import { renderWorkerDetail } from "./views.js";

/** @typedef {import("./api.js").AdminApi} AdminApi */

const input = (/** @type {string} */ id) => /** @type {HTMLInputElement} */ ($(id));

const state = {
  /** @type {AdminApi|null} */ api: null,
  /** @type {(err: unknown) => void} */ fail: () => {},
  /** The worker whose record is open. @type {string|null} */ worker: null,
  /** The question under a worker's record. @type {ConfirmBox|null} */ confirm: null,
  /** Names the bonus the form describes: the same bonus confirmed again (after an error)
   * pays once; changing the assignment, amount or reason makes it another bonus. */
  bonusKey: newKey(),
};

function newKey() {
  return `admin-${Date.now().toString(36)}-${Math.random().toString(36).slice(2, 8)}`;
}

function api() {
  if (!state.api) throw new Error("initWorkers was not called");
  return state.api;
}

/** @param {string} text  @param {"info"|"error"} [kind] */
function say(text, kind = "info") {
  showNotice($("worker-result"), text, kind);
}

/** @param {string} what  the action, e.g. "Blocking"  @param {unknown} err */
function failed(what, err) {
  showFailure($("worker-result"), what, err, state.fail);
}

/**
 * A page of workers with their stats (GET /api/crowd/workers).
 * @param {number} offset  @param {number} limit
 */
export function crowdWorkers(offset, limit) {
  return api().request("GET", `/crowd/workers?offset=${offset}&limit=${limit}`);
}

/** The worker whose record is open, for marking their row. */
export function openWorker() {
  return state.worker;
}

/** @param {string} workerId */
async function showWorker(workerId) {
  const id = encodeURIComponent(workerId);
  const [w, accounts] = await Promise.all([api().request("GET", `/crowd/workers/${id}`),
    api().request("GET", `/crowd/team?worker_id=${id}`)]);
  state.worker = workerId;
  // A portal account's email beside the provider's worker id: who the team member is.
  $("worker-title").textContent = workerName(w.worker_id, accounts[0]?.email);
  renderWorkerDetail({ facts: $("worker-facts"), chart: $("worker-chart"),
    assignments: $("worker-assignments"),
    bonusFor: /** @type {HTMLSelectElement} */ ($("bonus-assignment")) }, w);
  $("block").hidden = w.blocked;
  $("unblock").hidden = !w.blocked;
  $("bonus-form").hidden = !w.assignments.some((/** @type {any} */ a) => a.confirmed);
  $("no-bonus").hidden = !$("bonus-form").hidden;
  $("worker-detail").hidden = false;
  for (const row of document.querySelectorAll("#worker-rows tr")) {
    row.classList.toggle("selected", /** @type {HTMLElement} */ (row).dataset.worker === workerId);
  }
  return w;
}

/**
 * Ask before an action on a worker: the question and Confirm / Cancel under their record.
 * @param {string} question  @param {() => Promise<void>} action
 */
function confirmFirst(question, action) {
  say("");
  state.confirm?.ask(question, action);
}

function cancelConfirm() {
  if (state.confirm?.open) state.confirm.cancel();
}

/** @param {"block"|"unblock"} kind */
function askBlock(kind) {
  const worker = String(state.worker);
  const reason = input("block-reason").value.trim();
  if (kind === "block" && !reason) {
    say("Blocking needs a reason: the worker reads it.", "error");
    return;
  }
  const path = `/crowd/workers/${encodeURIComponent(worker)}/block`;
  confirmFirst(kind === "block" ? `Block ${worker}? They can take none of our HITs until `
    + "unblocked." : `Unblock ${worker}? They can take our HITs again.`, async () => {
    try {
      if (kind === "block") await api().request("POST", path, { reason });
      else await api().request("DELETE", reason ? `${path}?reason=${encodeURIComponent(reason)}`
        : path);
      await refreshWorker();
      say(`${worker} is ${kind === "block" ? "blocked" : "unblocked"}.`);
    } catch (err) {
      failed(kind === "block" ? "Blocking" : "Unblocking", err);
    }
  });
}

function askBonus() {
  const worker = String(state.worker);
  const assignment = /** @type {HTMLSelectElement} */ ($("bonus-assignment")).value;
  const amount = input("bonus-amount").value.trim();
  const reason = input("bonus-reason").value.trim();
  if (!assignment || !amount || !reason) {
    say("A bonus needs an assignment, an amount and a reason the worker reads.", "error");
    return;
  }
  const dollarsText = dollars(amount);
  confirmFirst(`Pay ${worker} a bonus of ${dollarsText} (plus the marketplace's fee) on `
    + `assignment ${assignment}?`, async () => {
    try {
      const key = state.bonusKey;
      const paid = await api().request("POST", `/crowd/assignments/${assignment}/bonus`,
        { amount, reason, key });
      state.bonusKey = newKey();
      await refreshWorker();
      say(paid.already_done ? `That bonus was already paid (${dollarsText}).`
        : `Paid ${worker} a ${dollarsText} bonus (fee $${paid.fee}) on assignment `
          + `${assignment}.`);
    } catch (err) {
      failed("The bonus", err);
    }
  });
}

/** The open record and its row again, after an action changed them. */
async function refreshWorker() {
  if (!state.worker) return;
  const w = await showWorker(state.worker);
  const row = document.querySelector(`#worker-rows tr[data-worker="${CSS.escape(w.worker_id)}"]`);
  const cell = row?.lastElementChild;
  if (cell) {
    cell.replaceChildren(w.blocked ? el("span", { class: "status status-reject" }, ["blocked"])
      : "no");
  }
}

function closeWorker() {
  state.worker = null;
  cancelConfirm();
  $("worker-detail").hidden = true;
  for (const row of document.querySelectorAll("#worker-rows tr.selected")) {
    row.classList.remove("selected");
  }
}

/**
 * @param {AdminApi} client
 * @param {(err: unknown) => void} fail  the page's handler of errors (a 401 signs out)
 */
export function initWorkers(client, fail) {
  Object.assign(state, { api: client, fail });
  $("worker-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-open-worker]");
    const id = button && /** @type {HTMLElement} */ (button).dataset.openWorker;
    if (id) {
      cancelConfirm();
      say("");
      showWorker(id).then(() => $("worker-detail").scrollIntoView({ block: "nearest" }))
        .catch(fail);
    }
  });
  $("worker-close").addEventListener("click", closeWorker);
  $("block").addEventListener("click", () => askBlock("block"));
  $("unblock").addEventListener("click", () => askBlock("unblock"));
  $("bonus").addEventListener("click", askBonus);
  for (const id of ["bonus-assignment", "bonus-amount", "bonus-reason"]) {
    $(id).addEventListener("input", () => { state.bonusKey = newKey(); });
  }
  state.confirm = new ConfirmBox($("worker-confirm"), fail);
}
