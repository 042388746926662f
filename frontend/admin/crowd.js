/**
 * The crowd on the admin page (#/crowd): every published unit of work (HIT) by task, with its
 * provider, places, decisions, holders, submissions and state; extend, expire (asked first)
 * and add places; a unit's assignments, work left "working" among them, each closed once
 * confirmed (its place freed, its saved labels kept).
 */

import { $, el } from "../common/dom.js";
import { dollars } from "../common/format.js";
import { showFailure, showNotice } from "../common/notice.js";
import { ConfirmBox } from "./confirm.js";
import { freePlaces, placesLine, workerName } from "./core/crowd-format.js";
import { when } from "./core/format.js";
import { badge } from "./views.js";

/** @typedef {import("./api.js").AdminApi} AdminApi */

const state = {
  /** @type {AdminApi|null} */ api: null,
  /** @type {(err: unknown) => void} */ fail: () => {},
  /** @type {ConfirmBox|null} */ confirm: null,
  /** The units listed. @type {any[]} */ units: [],
  /** The sequence whose units are listed (null: every sequence's). @type {number|null} */
  sequence: null,
  /** The unit whose assignments are open. @type {string|null} */ open: null,
};

function api() {
  if (!state.api) throw new Error("initCrowd was not called");
  return state.api;
}

/** @param {string} text  @param {"info"|"error"} [kind] */
function say(text, kind = "info") {
  showNotice($("crowd-result"), text, kind);
}

const number = (/** @type {string} */ id) =>
  Number(/** @type {HTMLInputElement} */ ($(id)).value);

/** @param {string} hitId  @param {string} action  @param {string} label */
function actionButton(hitId, action, label) {
  return el("button", { type: "button", "data-unit": hitId, "data-action": action,
    class: action === "expire" ? "danger" : "" }, [label]);
}

/** A time whose date and hour each stay whole where the column is narrow.
 * @param {string|null} iso */
function stamp(iso) {
  const [day, hour = ""] = when(iso).split(" ");
  return [el("span", { class: "nowrap" }, [day]), " ", el("span", { class: "nowrap" }, [hour])];
}

/** @param {any} u  a row of GET /api/crowd/units */
function unitRow(u) {
  const open = u.state === "open";
  return el("tr", { "data-unit": u.hit_id, "data-task": String(u.task_id), "data-state": u.state,
    class: u.hit_id === state.open ? "selected" : "" }, [
    el("td", { class: "unit-id" }, [el("button", { type: "button", class: "link", title:
      `${u.hit_id}: its assignments`, "data-unit": u.hit_id, "data-action": "assignments" },
    [u.hit_id]),
    el("div", { class: "muted small" }, [`round ${u.round} · ${dollars(u.reward)}`])]),
    el("td", {}, [el("a", { href: `#/sequences/${u.sequence_id}` }, [`task ${u.task_id}`]),
      el("div", { class: "muted small" }, [`${u.serial} · ${u.target_key}`]),
      u.reason ? el("div", { class: "muted small unit-reason", title: u.reason },
        [u.reason]) : ""]),
    el("td", { "data-col": "provider" }, [u.provider]),
    el("td", { class: "num", "data-col": "places", title: placesLine(u) }, [String(u.places),
      el("div", { class: "muted small" }, [open ? `${freePlaces(u)} free` : "–"])]),
    el("td", { class: "num", "data-col": "decided" }, [String(u.decided)]),
    el("td", { class: "num", "data-col": "holders" }, [String(u.holders)]),
    el("td", { class: "num", "data-col": "submitted" }, [String(u.submitted)]),
    el("td", { "data-col": "state" }, [badge(u.state, open ? "approve" : "reject")]),
    el("td", { "data-col": "dates" }, [...stamp(u.published_at), open ? "" : el("div", {
      class: "expired-at" }, ["expired ", ...stamp(u.expired_at)])]),
    el("td", {}, [el("div", { class: "unit-actions" }, [
      actionButton(u.hit_id, "extend", "Extend"), actionButton(u.hit_id, "add", "Add places"),
      open ? actionButton(u.hit_id, "expire", "Expire") : ""])]),
  ]);
}

/**
 * The units, newest task first: a sequence's, or (null) the newest thousand tasks' of all.
 * @param {number|null} [sequenceId]  the shown sequence's when not given
 */
export async function showCrowd(sequenceId = state.sequence) {
  const only = sequenceId === null ? "" : `&sequence_id=${sequenceId}`;
  state.units = await api().request("GET", `/crowd/units?limit=1000${only}`);
  state.sequence = sequenceId;
  $("crowd-title").textContent = sequenceId === null ? "Crowd" : `Crowd · sequence #${sequenceId}`;
  $("crowd-all").hidden = sequenceId === null;
  $("unit-rows").replaceChildren(...state.units.map(unitRow));
  $("no-units").hidden = state.units.length > 0;
  if (state.open && !state.units.some((u) => u.hit_id === state.open)) closeUnit();
  else if (state.open) await showAssignments(state.open);
}

/** @param {any} a  a row of GET /api/crowd/units/{hit_id}/assignments */
function assignmentRow(a) {
  return el("tr", { "data-assignment": String(a.assignment_id), "data-status": a.status }, [
    el("td", { class: "num" }, [String(a.assignment_id)]),
    el("td", { class: "clip", title: a.external_id }, [a.external_id]),
    el("td", { "data-col": "worker", title: "the provider's worker id, and the portal "
      + "account's email" }, [workerName(a.worker_id, a.account_email)]),
    el("td", { class: "nowrap" }, [when(a.started_at)]),
    el("td", { class: "nowrap" }, [when(a.saved_at)]),
    el("td", {}, [badge(a.status, a.status === "working" ? "running" : a.status === "approved"
      ? "approve" : a.status === "rejected" || a.status === "closed" ? "reject" : a.status)]),
    el("td", {}, [a.status === "working" ? el("button", { type: "button", class: "danger",
      "data-close": String(a.assignment_id) }, ["Close"]) : ""]),
  ]);
}

/** @param {string} hitId */
async function showAssignments(hitId) {
  const rows = await api().request("GET",
    `/crowd/units/${encodeURIComponent(hitId)}/assignments`);
  state.open = hitId;
  $("unit-title").textContent = `Assignments of ${hitId}`;
  $("unit-assignment-rows").replaceChildren(...rows.map(assignmentRow));
  $("no-unit-assignments").hidden = rows.length > 0;
  $("unit-detail").hidden = false;
  for (const row of document.querySelectorAll("#unit-rows tr")) {
    row.classList.toggle("selected", /** @type {HTMLElement} */ (row).dataset.unit === hitId);
  }
}

function closeUnit() {
  state.open = null;
  $("unit-detail").hidden = true;
  for (const row of document.querySelectorAll("#unit-rows tr.selected")) {
    row.classList.remove("selected");
  }
}

/**
 * Send one action on a unit, then show the units again with what it did.
 * @param {string} what  how the result reads  @param {string} path  @param {object} [body]
 */
async function send(what, path, body) {
  try {
    await api().request("POST", path, body);
    await showCrowd();
    say(what);
  } catch (err) {
    showFailure($("crowd-result"), "The action", err, state.fail);
  }
}

/** Which task a listed unit is of, as a question names it (the unit's id alone is opaque).
 * @param {string} hitId */
function unitNamed(hitId) {
  const u = state.units.find((unit) => unit.hit_id === hitId);
  return u ? ` It is task ${u.task_id} (view ${u.serial}, ${u.target_key}).` : "";
}

/** @param {string} hitId  @param {string} action */
function unitAction(hitId, action) {
  const path = `/crowd/hits/${encodeURIComponent(hitId)}`;
  say("");
  if (action === "assignments") {
    showAssignments(hitId).then(() => $("unit-detail").scrollIntoView({ block: "nearest" }))
      .catch(state.fail);
  } else if (action === "extend") {
    const hours = number("crowd-extend-hours");
    send(`${hitId} stays open ${hours} h from now.`, `${path}/extend`,
      { seconds: Math.round(hours * 3600) });
  } else if (action === "add") {
    const count = number("crowd-add-count");
    send(`Added ${count} place${count === 1 ? "" : "s"} to ${hitId}.`, `${path}/assignments`,
      { count });
  } else if (action === "expire") {
    state.confirm?.ask(`Expire ${hitId}?${unitNamed(hitId)} No one can take its free places `
      + "any more; work already taken can still be submitted.", () => send(
      `${hitId} is expired.`, `${path}/expire`), { yes: "Expire", danger: true });
  }
}

/** @param {string} assignmentId */
function askClose(assignmentId) {
  say("");
  state.confirm?.ask(`Close assignment ${assignmentId}? Its place is free again; what its `
    + "worker saved is kept but can no longer be changed or submitted.", async () => {
    try {
      await api().request("POST", `/crowd/assignments/${assignmentId}/close`);
      await showCrowd();
      say(`Assignment ${assignmentId} is closed; its place is free.`);
    } catch (err) {
      showFailure($("crowd-result"), "Closing", err, state.fail);
    }
  }, { yes: "Close it", danger: true });
}

/**
 * @param {AdminApi} client
 * @param {(err: unknown) => void} fail  the page's handler of errors (a 401 signs out)
 */
export function initCrowd(client, fail) {
  Object.assign(state, { api: client, fail, confirm: new ConfirmBox($("crowd-confirm"), fail) });
  $("unit-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-action]");
    const { unit, action } = /** @type {HTMLElement} */ (button ?? document.body).dataset;
    if (unit && action) unitAction(unit, action);
  });
  $("unit-assignment-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-close]");
    const id = button && /** @type {HTMLElement} */ (button).dataset.close;
    if (id) askClose(id);
  });
  $("unit-close").addEventListener("click", closeUnit);
  $("crowd-refresh").addEventListener("click", () => showCrowd().catch(fail));
}
