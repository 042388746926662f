/**
 * Pure helpers of the admin page's review queue (queue.js): what a listed report and the tally
 * say, which report opens and which one J, K or a decision moves to, what a decision needs
 * before it is sent and what it says once done, and which key does what. No DOM.
 *
 * A queue item is one row of GET /api/qc/queue: {assignment_id, outcome, provisional,
 * error_px, target_key, worker_id, sequence, swaps, issues}.
 */

/** @typedef {"approve"|"reject"|"bonus"} Decision */
/** @typedef {Decision|"next"|"previous"|"play"|"back"|"forward"} QueueAction */

/** @type {Readonly<Record<string, QueueAction>>} */
const KEY_ACTIONS = Object.freeze({
  a: "approve", r: "reject", b: "bonus", j: "next", n: "next", k: "previous",
  " ": "play", ArrowLeft: "back", ArrowRight: "forward",
});

/**
 * What a key does in the queue (letters in either case), or null.
 * @param {string} key  KeyboardEvent.key
 * @returns {QueueAction|null}
 */
export function queueKeyAction(key) {
  const name = key.length === 1 ? key.toLowerCase() : key;
  return Object.hasOwn(KEY_ACTIONS, name) ? KEY_ACTIONS[name] : null;
}

/**
 * @param {number} count @param {string} noun @returns {string} " · 2 swaps", "" for none
 */
function countPart(count, noun) {
  return count ? ` · ${count} ${noun}${count > 1 ? "s" : ""}` : "";
}

/**
 * The texts of a listed report: its error, what it is and where it is from.
 * @param {any} item  a queue item
 * @returns {{error: string, what: string, where: string}}
 */
export function queueRowText(item) {
  return {
    error: item.error_px === null ? "–" : `${item.error_px.toFixed(1)} px`,
    what: `#${item.assignment_id} ${item.target_key} · ${item.worker_id}`,
    where: `${item.sequence}${countPart(item.swaps, "swap")}${countPart(item.issues, "issue")}`,
  };
}

/**
 * The queue's tally: "4 waiting for an admin (the worst 200 listed)".
 * @param {number} total  reports waiting  @param {number} listed  reports on the page
 */
export function queueTally(total, listed) {
  return `${total} waiting for an admin`
    + (total > listed ? ` (the worst ${listed} listed)` : "");
}

/**
 * The item to open: the one asked for, or the first when it is not listed (null: none).
 * @param {any[]} items  @param {number|null} assignmentId
 */
export function itemToOpen(items, assignmentId) {
  return items.find((i) => i.assignment_id === assignmentId) ?? items[0] ?? null;
}

/**
 * The assignment `by` rows from the open one, held at the ends of the list; null when that is
 * the open one itself (or the list is empty).
 * @param {any[]} items  @param {number|null} current  @param {number} by  +1 next, -1 previous
 * @returns {number|null}
 */
export function movedTo(items, current, by) {
  const at = items.findIndex((i) => i.assignment_id === current);
  const next = items[Math.min(Math.max(at + by, 0), items.length - 1)];
  return next && next.assignment_id !== current ? next.assignment_id : null;
}

/**
 * The assignment to open after one is decided: the next in the list, else the one before it.
 * @param {any[]} items  @param {number} decided @returns {number|null}
 */
export function nextAfterDecision(items, decided) {
  const at = items.findIndex((i) => i.assignment_id === decided);
  const next = items[at + 1] ?? items[at - 1] ?? null;
  return next ? next.assignment_id : null;
}

/**
 * Why a decision cannot be sent as the form stands, or null when it can.
 * @param {Decision} kind  @param {string} feedback  trimmed  @param {string} amount  dollars
 */
export function decisionProblem(kind, feedback, amount) {
  if (kind === "reject" && !feedback) {
    return "A rejection needs feedback: tell the worker what was wrong.";
  }
  if (kind === "bonus" && !(Number(amount) > 0)) {
    return "A bonus needs an amount in dollars, more than $0.00.";
  }
  return null;
}

/**
 * What the queue says after paying a bonus.
 * @param {{amount: string, worker_id: string, already_done?: boolean}} paid  the reply
 * @param {number} assignmentId
 */
export function bonusPaidText(paid, assignmentId) {
  return `Bonus of $${paid.amount} paid to ${paid.worker_id} for assignment ${assignmentId}`
    + `${paid.already_done ? " (already paid)" : ""}.`;
}

/**
 * What the queue says after an approval or a rejection.
 * @param {"approve"|"reject"} kind  @param {number} assignmentId
 * @param {{already_done?: boolean}} done  the reply
 */
export function decidedText(kind, assignmentId, done) {
  return `${kind === "approve" ? "Approved" : "Rejected"} assignment ${assignmentId}`
    + `${done.already_done ? " (already done)" : ""}.`;
}

/**
 * What an admin is asked before a rejection, which is final for the worker; the feedback they
 * will read is shown under it.
 * @param {number} assignmentId
 */
export function rejectQuestion(assignmentId) {
  return `Reject assignment ${assignmentId}? This is final for the worker: it counts against `
    + "their approval rate and pays nothing. They will read:";
}
