/**
 * The notice line under a page's header (a `.notice` element), and how a failed request lands
 * in it: a refused sign-in (401) sends the page back to its sign-in form, anything else is shown
 * as an error.
 */

import { ApiError } from "./api.js";

/**
 * What an error says to people.
 * @param {unknown} err
 */
export function errorText(err) {
  return err instanceof Error ? err.message : String(err);
}

/**
 * Shows a message in a notice element (the page's line, or a result line under a form).
 * @param {HTMLElement} line  @param {string} text  "" hides it  @param {"info"|"error"} [kind]
 */
export function showNotice(line, text, kind = "info") {
  line.textContent = text;
  line.className = `notice ${kind}`;
  line.hidden = !text;
}

/**
 * Shows that an action failed in its result line, with the reply's status and detail; a refused
 * sign-in (401) goes to `fail` instead, the page's handler, which signs out.
 * @param {HTMLElement} line  @param {string} what  the action, e.g. "Publishing"
 * @param {unknown} err  @param {(err: unknown) => void} fail
 */
export function showFailure(line, what, err, fail) {
  if (err instanceof ApiError && err.status === 401) {
    fail(err);
    return;
  }
  const status = err instanceof ApiError ? ` (${err.status})` : "";
  showNotice(line, `${what} failed${status}: ${errorText(err)}`, "error");
}

/**
 * The page's notice line, with notify and fail.
 * @param {HTMLElement} line  the notice element
 * @param {() => void} signIn  shows the page's sign-in form
 */
export function noticeLine(line, signIn) {
  /** The text shown now survives the next navigation. */
  let kept = false;

  /**
   * @param {string} text  "" hides the line
   * @param {"info"|"error"} [kind]
   * @param {boolean} [acrossNavigation]  the text survives the next hash change
   */
  function notify(text, kind = "info", acrossNavigation = false) {
    kept = acrossNavigation;
    showNotice(line, text, kind);
  }

  /** @param {unknown} err */
  function fail(err) {
    if (err instanceof ApiError && err.status === 401) {
      signIn();
      notify("Please sign in again.", "error");
      return;
    }
    notify(errorText(err), "error");
  }

  /** A navigation clears the line unless its text was set to survive it. */
  function navigated() {
    if (!kept) notify("");
    kept = false;
  }

  return { notify, fail, navigated };
}
