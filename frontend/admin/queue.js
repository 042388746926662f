/**
 * The review queue (#/queue, #/queue/{assignment_id}): every report waiting for an admin
 * across sequences, worst first; the open one replayed in the review panel, decided with the
 * keyboard: A approve, R reject (with the feedback shown, prefilled from the evidence), B pay a
 * bonus, J or N next, K previous, Space play or pause, ← → step frames. Keys are ignored
 * while typing in a field. After a decision the next waiting report opens.
 */

import { ApiError } from "../common/api.js";
import { $, el } from "../common/dom.js";
import { errorText, showNotice } from "../common/notice.js";
import { evidenceFeedback } from "./core/replay.js";
import { ReviewPanel } from "./review.js";
import { badge } from "./views.js";

/** Reports a queue page lists. */
const QUEUE_PAGE = 200;
/** Names the bonus the queue pays, so that a second press never pays twice. */
const BONUS_KEY = "review";


/**
 * @param {import("./api.js").AdminApi} api
 * @param {(err: unknown) => void} fail  how the page reports an error it cannot place
 */
export function createQueue(api, fail) {
  /** @type {ReviewPanel|null} */ let panel = null;
  /** @type {any[]} */ let items = [];
  /** @type {number|null} */ let current = null;
  let busy = false;

  const feedback = () => /** @type {HTMLTextAreaElement} */ ($("queue-feedback"));
  const buttons = () => ["queue-approve", "queue-reject", "queue-bonus"]
    .map((id) => /** @type {HTMLButtonElement} */ ($(id)));

  /** @param {string} text @param {"info"|"error"} kind */
  function say(text, kind) {
    showNotice($("queue-result"), text, kind);
  }

  function renderList() {
    const list = $("queue-list");
    list.replaceChildren(...items.map((item) => {
      const error = item.error_px === null ? "–" : `${item.error_px.toFixed(1)} px`;
      const li = el("li", { "data-assignment": String(item.assignment_id),
        class: item.assignment_id === current ? "selected" : "" }, [
        el("a", { href: `#/queue/${item.assignment_id}` }, [
          el("span", { class: "q-head" }, [
            badge(item.outcome), item.provisional ? el("span", { class: "muted" },
              [" provisional"]) : "", el("span", { class: "q-error" }, [error])]),
          el("span", { class: "q-what" }, [`#${item.assignment_id} ${item.target_key} · `
            + `${item.worker_id}`]),
          el("span", { class: "q-where muted" }, [`${item.sequence}`
            + (item.swaps ? ` · ${item.swaps} swap${item.swaps > 1 ? "s" : ""}` : "")
            + (item.issues ? ` · ${item.issues} issue${item.issues > 1 ? "s" : ""}` : "")]),
        ]),
      ]);
      return li;
    }));
    $("queue-empty").hidden = items.length > 0;
    $("queue-work").hidden = items.length === 0;
  }

  /** @param {number|null} assignmentId  the one to open (the first when null or gone) */
  async function show(assignmentId) {
    const page = await api.request("GET", `/qc/queue?limit=${QUEUE_PAGE}&offset=0`);
    items = page.items;
    $("queue-tally").textContent = `${page.total} waiting for an admin`
      + (page.total > items.length ? ` (the worst ${items.length} listed)` : "");
    const open = items.find((i) => i.assignment_id === assignmentId) ?? items[0] ?? null;
    current = open ? open.assignment_id : null;
    renderList();
    if (!open) {
      panel?.close();
      return;
    }
    if (open.assignment_id !== assignmentId) {
      history.replaceState(null, "", `#/queue/${open.assignment_id}`);
    }
    const review = await api.request("GET", `/qc/reports/${open.assignment_id}/review`);
    if (current !== review.assignment_id) return;
    panel ??= new ReviewPanel($("queue-review"), api);
    panel.load(review);
    feedback().value = evidenceFeedback(review);
    say("", "info");
  }

  /** @param {number} by  +1 next, -1 previous */
  function move(by) {
    const at = items.findIndex((i) => i.assignment_id === current);
    const next = items[Math.min(Math.max(at + by, 0), items.length - 1)];
    if (next && next.assignment_id !== current) location.hash = `#/queue/${next.assignment_id}`;
  }

  /** @param {"approve"|"reject"|"bonus"} kind */
  async function decide(kind) {
    if (busy || current === null) return;
    const assignmentId = current;
    const text = feedback().value.trim();
    if (kind === "reject" && !text) {
      say("A rejection needs feedback: tell the worker what was wrong.", "error");
      return;
    }
    const amount = /** @type {HTMLInputElement} */ ($("queue-bonus-amount")).value.trim();
    if (kind === "bonus" && !(Number(amount) > 0)) {
      say("A bonus needs an amount in dollars, more than $0.00.", "error");
      return;
    }
    busy = true;
    for (const b of buttons()) b.disabled = true;
    try {
      if (kind === "bonus") {
        const paid = await api.request("POST", `/crowd/assignments/${assignmentId}/bonus`, {
          amount: Number(amount).toFixed(2), key: BONUS_KEY,
          reason: "A bonus for careful work: thank you." });
        say(`Bonus of $${paid.amount} paid to ${paid.worker_id} for assignment ${assignmentId}`
          + `${paid.already_done ? " (already paid)" : ""}.`, "info");
        return;
      }
      const done = kind === "approve" ? await api.approve(assignmentId, text)
        : await api.reject(assignmentId, text);
      const at = items.findIndex((i) => i.assignment_id === assignmentId);
      const next = items[at + 1] ?? items[at - 1] ?? null;
      await show(next ? next.assignment_id : null);
      history.replaceState(null, "", current === null ? "#/queue" : `#/queue/${current}`);
      say(`${kind === "approve" ? "Approved" : "Rejected"} assignment ${assignmentId}`
        + `${done.already_done ? " (already done)" : ""}.`, "info");
    } catch (err) {
      if (err instanceof ApiError && err.status === 401) fail(err);
      else say(errorText(err), "error");
    } finally {
      busy = false;
      for (const b of buttons()) b.disabled = false;
    }
  }

  /** @param {KeyboardEvent} e */
  function onKey(e) {
    if ($("queue-view").hidden || e.ctrlKey || e.metaKey || e.altKey) return;
    const target = /** @type {HTMLElement} */ (e.target);
    if (target.closest("input, textarea, select, [contenteditable]")) return;
    const key = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    /** @type {Record<string, () => void>} */
    const actions = {
      a: () => decide("approve"), r: () => decide("reject"), b: () => decide("bonus"),
      j: () => move(1), n: () => move(1), k: () => move(-1),
      " ": () => panel?.togglePlay(), ArrowLeft: () => panel?.step(-1),
      ArrowRight: () => panel?.step(1),
    };
    const act = actions[key];
    if (!act) return;
    e.preventDefault();
    act();
  }

  function bind() {
    $("queue-approve").addEventListener("click", () => decide("approve"));
    $("queue-reject").addEventListener("click", () => decide("reject"));
    $("queue-bonus").addEventListener("click", () => decide("bonus"));
    $("queue-next").addEventListener("click", () => move(1));
    $("queue-previous").addEventListener("click", () => move(-1));
    document.addEventListener("keydown", onKey);
    window.addEventListener("resize", () => panel?.layout());
  }

  return {
    bind,
    show,
    /** Stop the replay when the page leaves the queue. */
    leave: () => panel?.close(),
  };
}
