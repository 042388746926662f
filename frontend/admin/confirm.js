/**
 * A question asked on the page before an action that cannot be taken back (expire a unit of
 * work, close an assignment, reject, block, pay): its text, what the worker will read (if
 * anything), and Confirm / Cancel. Enter confirms, Escape cancels; nothing is sent before
 * Confirm. One box per place on the page; asking again replaces the question.
 */

import { el } from "../common/dom.js";

export class ConfirmBox {
  /**
   * @param {HTMLElement} box  an empty element with an id; its parts get ids from it
   *   (`{id}-text`, `{id}-detail`, `{id}-yes`, `{id}-no`)
   * @param {(err: unknown) => void} fail  where an error of the confirmed action goes
   */
  constructor(box, fail) {
    this.box = box;
    this.fail = fail;
    /** @type {(() => Promise<void>)|null} */ this.pending = null;
    /** Where the focus goes back to once the question is answered. */
    /** @type {HTMLElement|null} */ this.before = null;
    this.text = el("p", { id: `${box.id}-text` });
    this.detail = el("blockquote", { id: `${box.id}-detail`, class: "confirm-detail" });
    this.yes = el("button", { type: "button", id: `${box.id}-yes`, class: "ok" }, ["Confirm"]);
    this.no = el("button", { type: "button", id: `${box.id}-no` }, ["Cancel"]);
    box.classList.add("confirm");
    box.setAttribute("role", "alertdialog");
    box.setAttribute("aria-labelledby", this.text.id);
    box.replaceChildren(this.text, this.detail, el("div", { class: "bar" }, [this.yes, this.no]));
    box.hidden = true;
    this.yes.addEventListener("click", () => this.confirm());
    this.no.addEventListener("click", () => this.cancel());
    box.addEventListener("keydown", (e) => {
      if (e.key === "Escape") this.cancel();
      else if (e.key === "Enter" && e.target !== this.no) this.confirm();
      else return;
      e.preventDefault();
      e.stopPropagation();
    });
  }

  /** Whether a question waits for an answer. */
  get open() {
    return !this.box.hidden;
  }

  /**
   * Ask before ``action``; its focus on Confirm.
   * @param {string} question
   * @param {() => Promise<void>} action
   * @param {{detail?: string, yes?: string, danger?: boolean}} [options]  what the worker
   *   will read (quoted), Confirm's label, and whether it takes something away (shown red)
   */
  ask(question, action, options = {}) {
    if (!this.open) {
      this.before = document.activeElement instanceof HTMLElement ? document.activeElement
        : null;
    }
    this.pending = action;
    this.text.textContent = question;
    this.detail.textContent = options.detail || "";
    this.detail.hidden = !options.detail;
    this.yes.textContent = options.yes || "Confirm";
    this.yes.className = options.danger ? "danger" : "ok";
    this.box.hidden = false;
    this.yes.focus();
    this.box.scrollIntoView({ block: "nearest" });
  }

  /** Drop the question; nothing is done. */
  cancel() {
    this.pending = null;
    this.box.hidden = true;
    this.before?.focus();
    this.before = null;
  }

  /** Do what was asked about, once. */
  confirm() {
    const action = this.pending;
    this.cancel();
    if (action) action().catch(this.fail);
  }
}
