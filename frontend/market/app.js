/**
 * The worker portal: sign in (or register with an invite), find HITs, preview, accept, work in
 * the annotation page framed exactly as MTurk frames it, and see earnings and feedback.
 */

import { ApiError, PortalApi } from "./api.js";
import { parseRoute } from "./format.js";
import { renderEarnings, renderHits, taskFrame } from "./views.js";

const api = new PortalApi(window.sessionStorage);
const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));
const VIEWS = ["login-view", "hits-view", "preview-view", "work-view", "earnings-view"];
/** A notice set just before a navigation survives it; any other navigation clears it. */
let keepNotice = false;

/** @param {string} id */
function show(id) {
  for (const view of VIEWS) $(view).hidden = view !== id;
  // The HIT pages keep their chrome compact so the framed page gets the window.
  document.body.dataset.view = id;
  $("nav").hidden = id === "login-view";
}

/**
 * @param {string} text
 * @param {"info"|"error"} [kind]
 * @param {boolean} [acrossNavigation]  the text survives the next hash change
 */
function notify(text, kind = "info", acrossNavigation = false) {
  keepNotice = acrossNavigation;
  const notice = $("notice");
  notice.textContent = text;
  notice.className = `notice ${kind}`;
  notice.hidden = !text;
}

/** @param {unknown} err */
function fail(err) {
  if (err instanceof ApiError && err.status === 401) {
    show("login-view");
    notify("Please sign in again.", "error");
    return;
  }
  notify(err instanceof Error ? err.message : String(err), "error");
}

async function showHits() {
  const hits = await api.hits();
  renderHits(/** @type {HTMLTableSectionElement} */ ($("hit-rows")), hits);
  $("no-hits").hidden = hits.length > 0;
  show("hits-view");
}

/** @param {string} hitId */
async function showPreview(hitId) {
  const hit = await api.preview(hitId);
  $("preview-title").textContent = hit.title;
  $("preview-description").textContent = hit.description;
  const accept = /** @type {HTMLButtonElement} */ ($("accept"));
  accept.dataset.hit = hit.hit_id;
  accept.disabled = !hit.can_accept;
  $("preview-frame").replaceChildren(hit.preview_url
    ? taskFrame(hit.preview_url)
    : document.createTextNode("This HIT has no page to preview here."));
  show("preview-view");
}

/** @param {string} assignmentId */
async function showWork(assignmentId) {
  const assignment = await api.assignment(assignmentId);
  if (!assignment.work_url) {
    location.hash = "#/earnings";
    return;
  }
  $("work-title").textContent = assignment.title;
  $("work-deadline").textContent = new Date(assignment.deadline).toLocaleTimeString();
  $("return").dataset.assignment = assignmentId;
  const frame = taskFrame(assignment.work_url);
  // The page inside posts its form to /mturk/externalSubmit and the frame navigates; each load
  // asks the marketplace whether the assignment is still open.
  frame.addEventListener("load", () => checkSubmitted(assignmentId).catch(fail));
  $("work-frame").replaceChildren(frame);
  show("work-view");
}

/** @param {string} assignmentId */
async function checkSubmitted(assignmentId) {
  if (parseRoute(location.hash).id !== assignmentId) return;
  const assignment = await api.assignment(assignmentId);
  if (assignment.status === "Accepted") return;
  notify(`Submitted: “${assignment.title}”. Thank you!`, "info", true);
  location.hash = "#/hits";
}

async function showEarnings() {
  const data = await api.assignments();
  renderEarnings($("earnings-summary"),
    /** @type {HTMLTableSectionElement} */ ($("assignment-rows")), data);
  show("earnings-view");
}

async function route() {
  if (!api.token) {
    show("login-view");
    return;
  }
  const { view, id } = parseRoute(location.hash);
  try {
    if (view === "preview" && id) await showPreview(id);
    else if (view === "work" && id) await showWork(id);
    else if (view === "earnings") await showEarnings();
    else await showHits();
  } catch (err) {
    fail(err);
  }
}

/** @param {SubmitEvent} event */
async function onLogin(event) {
  event.preventDefault();
  const form = /** @type {HTMLFormElement} */ (event.target);
  const data = new FormData(form);
  try {
    await api.login(String(data.get("email")), String(data.get("password")));
    notify("");
    await loadMe();
    location.hash = "#/hits";
    await route();
  } catch (err) {
    notify(err instanceof Error ? err.message : String(err), "error");
  }
}

/** @param {SubmitEvent} event */
async function onRegister(event) {
  event.preventDefault();
  const data = new FormData(/** @type {HTMLFormElement} */ (event.target));
  const invite = new URLSearchParams(location.search).get("invite") || "";
  try {
    await api.register(invite, String(data.get("email")), String(data.get("password")));
    history.replaceState(null, "", location.pathname);
    $("register").hidden = true;
    notify("Account created: sign in with your email and password.");
  } catch (err) {
    notify(err instanceof Error ? err.message : String(err), "error");
  }
}

async function onAccept() {
  try {
    const assignment = await api.accept(String($("accept").dataset.hit));
    location.hash = `#/work/${encodeURIComponent(assignment.assignment_id)}`;
  } catch (err) {
    fail(err);
  }
}

async function onReturn() {
  try {
    await api.giveBack(String($("return").dataset.assignment));
    notify("HIT returned.", "info", true);
    location.hash = "#/hits";
  } catch (err) {
    fail(err);
  }
}

async function loadMe() {
  const me = await api.me();
  $("who").textContent = `${me.email} · ${me.worker_id}`;
}

async function signOut() {
  try {
    await api.logout();
  } catch {
    // The token is forgotten here either way; the server lets it expire.
  }
  notify("");
  show("login-view");
}

function start() {
  $("login").addEventListener("submit", (e) => onLogin(/** @type {SubmitEvent} */ (e)));
  $("register").addEventListener("submit", (e) => onRegister(/** @type {SubmitEvent} */ (e)));
  $("register").hidden = !new URLSearchParams(location.search).get("invite");
  $("accept").addEventListener("click", onAccept);
  $("return").addEventListener("click", onReturn);
  $("sign-out").addEventListener("click", signOut);
  window.addEventListener("hashchange", () => {
    if (!keepNotice) notify("");
    keepNotice = false;
    route();
  });
  if (api.token) loadMe().catch(fail);
  route();
}

start();
