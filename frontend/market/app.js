/**
 * The worker portal: sign in (or register with an invite), find HITs, preview, accept, work in
 * the annotation page framed exactly as MTurk frames it, and see earnings and feedback.
 */

import { SUBMITTED_MESSAGE } from "../annotate/core/completion.js";
import { $ } from "../common/dom.js";
import { errorText, noticeLine } from "../common/notice.js";
import { startSession } from "../common/session.js";
import { PortalApi } from "./api.js";
import { inviteOf, parseRoute } from "./core/route.js";
import { renderEarnings, renderHits, taskFrame } from "./views.js";

const api = new PortalApi(window.sessionStorage);
const VIEWS = ["login-view", "hits-view", "preview-view", "work-view", "earnings-view"];
/** The views that frame an annotation page, and the box its frame sits in. */
const FRAME_BOXES = { "preview-view": "preview-frame", "work-view": "work-frame" };
const notice = noticeLine($("notice"), () => show("login-view"));
const { notify, fail } = notice;

/**
 * Shows one view. A framed page leaves with its view: the preview's annotation app is
 * unloaded once the HIT is accepted, so one app runs at a time.
 * @param {string} id
 */
function show(id) {
  for (const view of VIEWS) $(view).hidden = view !== id;
  for (const [view, box] of Object.entries(FRAME_BOXES)) {
    if (view !== id) $(box).replaceChildren();
  }
  // The HIT pages keep their chrome compact so the framed page gets the window.
  document.body.dataset.view = id;
  $("nav").hidden = id === "login-view";
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

/**
 * The framed page says its work is submitted (a crowd that completes "back to the portal's
 * list"): believed only from the work frame, at the origin its page was loaded from. The page
 * has already handed its assignment in to the marketplace (annotate/core/completion.js).
 * @param {MessageEvent} event
 */
function onFrameMessage(event) {
  const frame = /** @type {HTMLIFrameElement | null} */ ($("work-frame").querySelector("iframe"));
  if (!frame || event.source !== frame.contentWindow) return;
  if (event.origin !== new URL(frame.src, location.href).origin) return;
  if (!event.data || event.data.type !== SUBMITTED_MESSAGE) return;
  notify(`Submitted: “${$("work-title").textContent}”. Thank you!`, "info", true);
  location.hash = "#/hits";
}

async function showEarnings() {
  const data = await api.assignments();
  renderEarnings($("earnings-summary"),
    /** @type {HTMLTableSectionElement} */ ($("assignment-rows")), data);
  show("earnings-view");
}

/**
 * The HIT or assignment a signed-out visitor asked for (a link opened in a new tab), where the
 * sign-in lands instead of the list; "" when none was asked for.
 */
let askedFor = "";

/** Where a sign-in lands: the page asked for before it, once; else the list. */
function afterSignIn() {
  const hash = askedFor || "#/hits";
  askedFor = "";
  $("login-next").hidden = true;
  return hash;
}

async function route() {
  if (!api.token) {
    askedFor = ["preview", "work"].includes(parseRoute(location.hash).view) ? location.hash : "";
    $("login-next").hidden = !askedFor;
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

/** The invite token of the registration link this page was opened with ("" if none). */
let invite = "";

/**
 * A new member registers with their invite and is signed in at once, on the list of HITs.
 * @param {SubmitEvent} event
 */
async function onRegister(event) {
  event.preventDefault();
  const data = new FormData(/** @type {HTMLFormElement} */ (event.target));
  const [email, password] = [String(data.get("email")), String(data.get("password"))];
  try {
    await api.register(invite, email, password);
    invite = "";
    $("register").hidden = true;
    await api.login(email, password);
    await loadMe();
    notify(`Account created: you are signed in as ${email}.`, "info", true);
    location.hash = "#/hits";
    await route();
  } catch (err) {
    notify(errorText(err), "error");
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

function start() {
  invite = inviteOf(location.hash, location.search);
  // Out of the address at once: out of the history, and of what a reload or a copied link
  // carries. The registration form keeps it.
  if (invite) history.replaceState(null, "", location.pathname);
  $("register").addEventListener("submit", (e) => onRegister(/** @type {SubmitEvent} */ (e)));
  $("register").hidden = !invite;
  // An invited newcomer has no account yet: creating it comes first.
  if (invite) $("login-view").prepend($("register"));
  $("accept").addEventListener("click", onAccept);
  $("return").addEventListener("click", onReturn);
  window.addEventListener("message", onFrameMessage);
  startSession({ api, notice, signedOut: () => show("login-view"), loadMe, route, home: afterSignIn });
}

start();
