/**
 * The team on the admin page (#/team): the worker portal's accounts with their decided work,
 * a one-time invite link to hand out (its token in the link's fragment, which no browser
 * sends, so it never lands in an access log), and an account made directly.
 */

import { $, el } from "../common/dom.js";
import { showFailure, showNotice } from "../common/notice.js";
import { when } from "./core/format.js";
import { badge } from "./views.js";

/** @typedef {import("./api.js").AdminApi} AdminApi */

const state = {
  /** @type {AdminApi|null} */ api: null,
  /** @type {(err: unknown) => void} */ fail: () => {},
};

function api() {
  if (!state.api) throw new Error("initTeam was not called");
  return state.api;
}

const input = (/** @type {string} */ id) => /** @type {HTMLInputElement} */ ($(id));

/** @param {string} text  @param {"info"|"error"} [kind] */
function say(text, kind = "info") {
  showNotice($("team-result"), text, kind);
}

/** The team's accounts, oldest first. */
export async function showTeam() {
  const members = await api().request("GET", "/crowd/team?limit=1000");
  $("team-rows").replaceChildren(...members.map((/** @type {any} */ m) => el("tr", {
    "data-worker": m.worker_id }, [
    el("td", { "data-col": "email" }, [m.email]),
    el("td", { "data-col": "worker" }, [el("code", {}, [m.worker_id])]),
    el("td", { class: "num", "data-col": "approved" }, [String(m.approved)]),
    el("td", { class: "num", "data-col": "rejected" }, [String(m.rejected)]),
    el("td", { class: "nowrap" }, [when(m.created_at)]),
    el("td", {}, [m.active ? "yes" : badge("no", "reject")]),
  ])));
  $("no-team").hidden = members.length > 0;
}

/** @param {SubmitEvent} event */
async function invite(event) {
  event.preventDefault();
  const hours = Number(input("invite-hours").value);
  try {
    const made = await api().request("POST", "/portal/invites", { ttl_hours: hours });
    input("invite-url").value = made.url;
    $("invite-expires").textContent = `Works once, until ${when(made.expires_at)} UTC.`;
    $("invite-made").hidden = false;
    input("invite-url").select();
    say("");
  } catch (err) {
    showFailure($("team-result"), "Making the invite", err, state.fail);
  }
}

async function copyInvite() {
  await navigator.clipboard.writeText(input("invite-url").value);
  say("The invite link is copied.");
}

/** @param {SubmitEvent} event */
async function createAccount(event) {
  event.preventDefault();
  const form = /** @type {HTMLFormElement} */ (event.target);
  const email = input("account-email").value.trim();
  try {
    const made = await api().request("POST", "/portal/workers",
      { email, password: input("account-password").value });
    form.reset();
    await showTeam();
    say(`${made.email} can sign in to the worker portal; their worker id is ${made.worker_id}.`);
  } catch (err) {
    showFailure($("team-result"), `Creating the account of ${email}`, err, state.fail);
  }
}

/**
 * @param {AdminApi} client
 * @param {(err: unknown) => void} fail  the page's handler of errors (a 401 signs out)
 */
export function initTeam(client, fail) {
  Object.assign(state, { api: client, fail });
  $("invite-form").addEventListener("submit", (e) => invite(/** @type {SubmitEvent} */ (e)));
  $("invite-copy").addEventListener("click", () => copyInvite().catch((err) =>
    showFailure($("team-result"), "Copying", err, fail)));
  $("account-form").addEventListener("submit",
    (e) => createAccount(/** @type {SubmitEvent} */ (e)));
}
