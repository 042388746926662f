/**
 * The review queue (#/queue, #/queue/{assignment_id}): every report waiting for an admin
 * across sequences, worst first; the open one replayed in the review panel, decided with the
 * keyboard: A approve, R reject (asked first, with the feedback shown, prefilled from the
 * evidence; Enter confirms, Escape cancels), B pay a bonus, J or N next, K previous, Space
 * play or pause, ← → step frames. Keys are ignored while typing in a field or while a
 * rejection is asked about. After a decision the next waiting report opens.
 */

import { ApiError } from "../common/api.js";
import { $, el } from "../common/dom.js";
import { errorText, showNotice } from "../common/notice.js";
import {
  bonusPaidText, decidedText, decisionProblem, itemToOpen, movedTo, nextAfterDecision,
  queueKeyAction, queueRowText, queueTally, rejectQuestion,
} from "./core/queue-core.js";
import { evidenceFeedback } from "./core/replay.js";
import { ConfirmBox } from "./confirm.js";
import { ReviewPanel } from "./review.js";
import { badge } from "./views.js";

/** Reports a queue page lists. */
const QUEUE_PAGE = 200;
/** Names the bonus the queue pays, so that a second press never pays twice. */
const BONUS_KEY = "review";

/**
 * A listed report, linked to its place in the queue.
 * @param {any} item  a row of GET /api/qc/queue  @param {number|null} current  the open one
 */
function queueRow(item, current) {
  const text = queueRowText(item);
  return el("li", { "data-assignment": String(item.assignment_id),
    class: item.assignment_id === current ? "selected" : "" }, [
    el("a", { href: `#/queue/${item.assignment_id}` }, [
      el("span", { class: "q-head" }, [
        badge(item.outcome), item.provisional ? el("span", { class: "muted" },
          [" provisional"]) : "", el("span", { class: "q-error" }, [text.error])]),
      el("span", { class: "q-what" }, [text.what]),
      el("span", { class: "q-where muted" }, [text.where]),
    ]),
  ]);
}

const feedback = () => /** @type {HTMLTextAreaElement} */ ($("queue-feedback"));

/** @param {boolean} disabled */
function disableDecisions(disabled) {
  for (const id of ["queue-approve", "queue-reject", "queue-bonus"]) {
    /** @type {HTMLButtonElement} */ ($(id)).disabled = disabled;
  }
}

/** @param {string} text @param {"info"|"error"} kind */
function say(text, kind) {
  showNotice($("queue-result"), text, kind);
}

/** The queue view: its list, the open report's review panel and the decisions on it. */
export class ReviewQueue {
  /**
   * @param {import("./api.js").AdminApi} api
   * @param {(err: unknown) => void} fail  how the page reports an error it cannot place
   */
  constructor(api, fail) {
    this.api = api;
    this.fail = fail;
    /** @type {ReviewPanel|null} */ this.panel = null;
    /** Asks before a rejection. */
    this.confirm = new ConfirmBox($("queue-confirm"), fail);
    /** @type {any[]} */ this.items = [];
    /** @type {number|null} */ this.current = null;
    this.busy = false;
  }

  renderList() {
    $("queue-list").replaceChildren(...this.items.map((item) => queueRow(item, this.current)));
    $("queue-empty").hidden = this.items.length > 0;
    $("queue-work").hidden = this.items.length === 0;
  }

  /** @param {number|null} assignmentId  the one to open (the first when null or gone) */
  async show(assignmentId) {
    const page = await this.api.request("GET", `/qc/queue?limit=${QUEUE_PAGE}&offset=0`);
    this.items = page.items;
    $("queue-tally").textContent = queueTally(page.total, this.items.length);
    const open = itemToOpen(this.items, assignmentId);
    this.current = open ? open.assignment_id : null;
    this.renderList();
    if (!open) {
      this.panel?.close();
      return;
    }
    if (open.assignment_id !== assignmentId) {
      history.replaceState(null, "", `#/queue/${open.assignment_id}`);
    }
    const review = await this.api.request("GET", `/qc/reports/${open.assignment_id}/review`);
    if (this.current !== review.assignment_id) return;
    this.panel ??= new ReviewPanel($("queue-review"), this.api);
    this.panel.load(review);
    feedback().value = evidenceFeedback(review);
    say("", "info");
  }

  /** @param {number} by  +1 next, -1 previous */
  move(by) {
    const next = movedTo(this.items, this.current, by);
    if (next !== null) location.hash = `#/queue/${next}`;
  }

  /** @param {"approve"|"reject"|"bonus"} kind */
  async decide(kind) {
    if (this.busy || this.current === null) return;
    const assignmentId = this.current;
    const text = feedback().value.trim();
    const amount = /** @type {HTMLInputElement} */ ($("queue-bonus-amount")).value.trim();
    const problem = decisionProblem(kind, text, amount);
    if (problem) {
      say(problem, "error");
      return;
    }
    if (kind === "reject") {
      // A rejection is final for the worker (their approval rate, their pay): asked first,
      // with the feedback they will read; nothing is sent before Confirm.
      say("", "info");
      this.confirm.ask(rejectQuestion(assignmentId), () => this.run(kind, assignmentId, text,
        amount), { detail: text, yes: "Reject", danger: true });
      return;
    }
    await this.run(kind, assignmentId, text, amount);
  }

  /**
   * Send a decision already checked (and for a rejection, confirmed).
   * @param {"approve"|"reject"|"bonus"} kind @param {number} assignmentId
   * @param {string} text  feedback  @param {string} amount  a bonus, dollars
   */
  async run(kind, assignmentId, text, amount) {
    if (this.busy || this.current !== assignmentId) return;
    this.busy = true;
    disableDecisions(true);
    try {
      if (kind === "bonus") await this.payBonus(assignmentId, amount);
      else await this.settle(kind, assignmentId, text);
    } catch (err) {
      if (err instanceof ApiError && err.status === 401) this.fail(err);
      else say(errorText(err), "error");
    } finally {
      this.busy = false;
      disableDecisions(false);
    }
  }

  /** @param {number} assignmentId @param {string} amount  dollars */
  async payBonus(assignmentId, amount) {
    const paid = await this.api.request("POST", `/crowd/assignments/${assignmentId}/bonus`, {
      amount: Number(amount).toFixed(2), key: BONUS_KEY,
      reason: "A bonus for careful work: thank you." });
    say(bonusPaidText(paid, assignmentId), "info");
  }

  /**
   * Approve or reject, then open the next report waiting.
   * @param {"approve"|"reject"} kind @param {number} assignmentId @param {string} text feedback
   */
  async settle(kind, assignmentId, text) {
    const done = kind === "approve" ? await this.api.approve(assignmentId, text)
      : await this.api.reject(assignmentId, text);
    await this.show(nextAfterDecision(this.items, assignmentId));
    history.replaceState(null, "", this.current === null ? "#/queue"
      : `#/queue/${this.current}`);
    say(decidedText(kind, assignmentId, done), "info");
  }

  /** @param {KeyboardEvent} e */
  onKey(e) {
    if ($("queue-view").hidden || this.confirm.open || e.ctrlKey || e.metaKey || e.altKey) {
      return;
    }
    const target = /** @type {HTMLElement} */ (e.target);
    if (target.closest("input, textarea, select, [contenteditable]")) return;
    const action = queueKeyAction(e.key);
    if (!action) return;
    e.preventDefault();
    if (action === "approve" || action === "reject" || action === "bonus") this.decide(action);
    else if (action === "next" || action === "previous") this.move(action === "next" ? 1 : -1);
    else if (action === "play") this.panel?.togglePlay();
    else this.panel?.step(action === "forward" ? 1 : -1);
  }

  bind() {
    $("queue-approve").addEventListener("click", () => this.decide("approve"));
    $("queue-reject").addEventListener("click", () => this.decide("reject"));
    $("queue-bonus").addEventListener("click", () => this.decide("bonus"));
    $("queue-next").addEventListener("click", () => this.move(1));
    $("queue-previous").addEventListener("click", () => this.move(-1));
    document.addEventListener("keydown", (e) => this.onKey(e));
    window.addEventListener("resize", () => this.panel?.layout());
  }

  /** Stop the replay when the page leaves the queue (or moves on): a question still asked
   * is dropped. */
  leave() {
    if (this.confirm.open) this.confirm.cancel();
    this.panel?.close();
  }
}
