/**
 * The signed-in frame of the staff pages (admin, worker portal): the sign-in form (#login),
 * the sign-out button (#sign-out), who is signed in, and a route on every hash change.
 */

import { $ } from "./dom.js";
import { errorText } from "./notice.js";

/**
 * @typedef {Object} Session
 * @property {{token: string|null, login: (email: string, password: string) => Promise<unknown>,
 *             logout: () => Promise<void>}} api
 * @property {ReturnType<typeof import("./notice.js").noticeLine>} notice
 * @property {() => void} signedOut   shows the sign-in view
 * @property {() => Promise<void>} loadMe  shows who is signed in
 * @property {() => Promise<void>} route   shows the view of the page's hash
 * @property {string | (() => string)} [home]  the hash a sign-in lands on (else the hash
 *   stays); a function is asked at each sign-in (a deep link asked for before it)
 */

/** Binds the form, the button and hash changes, then shows the page's first view.
 * @param {Session} session */
export function startSession(session) {
  const { api, notice } = session;
  $("login").addEventListener("submit", (e) => signIn(session, /** @type {SubmitEvent} */ (e)));
  $("sign-out").addEventListener("click", async () => {
    await api.logout();
    notice.notify("");
    session.signedOut();
  });
  window.addEventListener("hashchange", () => {
    notice.navigated();
    session.route();
  });
  if (api.token) session.loadMe().catch(notice.fail);
  session.route();
}

/** @param {Session} session @param {SubmitEvent} event */
async function signIn(session, event) {
  event.preventDefault();
  const data = new FormData(/** @type {HTMLFormElement} */ (event.target));
  try {
    await session.api.login(String(data.get("email")), String(data.get("password")));
    session.notice.notify("");
    await session.loadMe();
    const home = typeof session.home === "function" ? session.home() : session.home;
    if (home) location.hash = home;
    await session.route();
  } catch (err) {
    session.notice.notify(errorText(err), "error");
  }
}
