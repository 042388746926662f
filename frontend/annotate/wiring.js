/**
 * Buttons of the page, the editing tools' controls (copy pose, go to frame, hide and lock, the
 * tool message), and the two steps of an object task:
 *   step 1: pick 2 distinctive points on the highlighted object (placed on the current frame);
 *   step 2: track them through the clip (the same editor, 2 points).
 *
 * Hidden and locked points are view settings: kept in localStorage per assignment (or task, in
 * a preview), never sent to the server.
 */

import { $ } from "../common/dom.js";
import { parseFrame } from "./core/tools.js";
import { PLAY_FPS } from "./editor.js";

/** How long a tool message stays up, ms: a refusal longer, as it asks for something. */
const MESSAGE_MS = { info: 4000, error: 9000 };

/**
 * Binds the toolbar, transport and point buttons.
 * @param {any} page  app.js's page object
 * @param {{requestSubmit: () => void}} hooks
 */
export function wireControls(page, { requestSubmit }) {
  const { editor } = page;
  const on = (id, fn) => $(id).addEventListener("click", (e) => {
    page.clock.activity();
    fn(e);
    // A focused button would also "click" on Space, which is play/pause here.
    if (e.currentTarget instanceof HTMLElement) e.currentTarget.blur();
  });
  on("undo", () => editor.undo());
  on("redo", () => editor.redo());
  on("back10", () => editor.step(-10));
  on("back1", () => editor.step(-1));
  on("fwd1", () => editor.step(1));
  on("fwd10", () => editor.step(10));
  on("play", () => editor.togglePlay());
  on("toggle-occluded", () => editor.toggleOccluded());
  on("next-point", () => editor.nextPoint());
  on("delete-keyframe", () => editor.deleteKeyframe());
  on("show-shortcuts", () => $("shortcuts").showModal());
  on("submit", () => {
    if (refuseOffObject(page)) return;
    requestSubmit();
  });
  on("copy-pose", () => editor.copyPreviousPose());
  // Narrow windows open the instructions over the image (style.css): start with them closed.
  if (window.matchMedia("(max-width: 1279px)").matches) {
    $("instructions").hidden = true;
    $("toggle-instructions").setAttribute("aria-pressed", "false");
  }
  on("toggle-instructions", (e) => {
    const panel = $("instructions");
    panel.hidden = !panel.hidden;
    e.currentTarget.setAttribute("aria-pressed", String(!panel.hidden));
  });
  $("submit-dialog").querySelector(".submit-cancel")
    .addEventListener("click", () => $("submit-dialog").close());
  const fps = /** @type {HTMLSelectElement} */ ($("fps"));
  fps.addEventListener("change", () => {
    const value = Number(fps.value);
    if (PLAY_FPS.includes(value)) editor.setFps(value);
    fps.blur();
  });
  window.__dexlabel.imageToClient = (x, y) => imageToClient(editor, x, y);
  wireTools(page);
}

/**
 * Shows what a tool did or why an edit was refused, over the top of the image.
 * @param {HTMLElement} box  #tool-message
 * @param {string|string[]} text  several lines become a list
 * @param {"info"|"error"} kind
 */
export function showToolMessage(box, text, kind) {
  const lines = Array.isArray(text) ? text : [text];
  box.dataset.kind = kind;
  box.replaceChildren(...lines.map((line, i) => {
    const el = document.createElement(i === 0 ? "p" : "li");
    el.textContent = line;
    return el;
  }));
  box.hidden = lines.length === 0 || !lines[0];
  clearTimeout(Number(box.dataset.timer));
  box.dataset.timer = String(setTimeout(() => { box.hidden = true; }, MESSAGE_MS[kind]));
}

/**
 * Refuses to open the submit dialog while a landmark lies off the highlighted object, listing
 * them. @returns {boolean} whether it refused
 */
function refuseOffObject(page) {
  const problems = page.editor.offObjectProblems();
  if (problems.length === 0) return false;
  showToolMessage($("tool-message"), [
    "Cannot submit: move these landmarks onto the highlighted object (or mark them occluded):",
    ...problems,
  ], "error");
  return true;
}

/** Where the hidden and locked points of this assignment are kept in localStorage. */
function viewKey(page) {
  const a = page.data && page.data.assignment;
  return a ? `dexlabel:view:assignment:${a.id}` : `dexlabel:view:task:${page.task.id}`;
}

/** Hide/lock toggles, their persistence, go to frame and the tool message. */
function wireTools(page) {
  const { editor, pointList, storage } = page;
  const key = viewKey(page);
  try {
    const saved = storage ? JSON.parse(storage.getItem(key) || "null") : null;
    const valid = (p) => Number.isInteger(p) && p >= 0 && p < editor.numPoints;
    for (const p of (saved && saved.hidden) || []) if (valid(p)) editor.hidden.add(p);
    for (const p of (saved && saved.locked) || []) if (valid(p)) editor.locked.add(p);
  } catch {
    // An unreadable entry is only a view setting: start with every point shown and unlocked.
  }
  let kept = "";
  /** Writes the settings when they changed (the hook runs on every frame step). */
  const keep = () => {
    const now = JSON.stringify({ hidden: [...editor.hidden], locked: [...editor.locked] });
    if (!storage || now === kept) return;
    kept = now;
    try {
      storage.setItem(key, now);
    } catch {
      // Storage full or refused: the settings still hold for this page.
    }
  };
  pointList.onToggle = (point, what) => {
    page.clock.activity();
    if (what === "hide") editor.setHidden(point, !editor.hidden.has(point));
    else editor.setLocked(point, !editor.locked.has(point));
  };
  page.refreshHooks.push(() => {
    pointList.setViewState(editor.hidden, editor.locked);
    $("copy-pose").toggleAttribute("disabled", editor.readOnly);
    keep();
  });
  if (page.task.kind !== "hand") {
    $("drag-hint").textContent = "Shift+drag a landmark: both move together.";
  }
  const box = $("tool-message");
  editor.onMessage = (text, kind) => showToolMessage(box, text, kind);
  box.addEventListener("click", () => { box.hidden = true; });
  wireFrameInput(page);
}

/** The go-to-frame box: Enter goes there, or says why not; Escape gives the keys back. */
function wireFrameInput(page) {
  const { editor } = page;
  const input = /** @type {HTMLInputElement} */ ($("goto-frame"));
  const error = $("goto-error");
  input.placeholder = `0-${editor.numFrames - 1}`;
  const go = () => {
    const { frame, error: why } = parseFrame(input.value, editor.numFrames);
    error.textContent = why || "";
    error.hidden = !why;
    input.setAttribute("aria-invalid", String(Boolean(why)));
    if (frame === null) return;
    editor.goto(frame);
    input.value = "";
    input.blur();
  };
  input.addEventListener("keydown", (e) => {
    if (e.key === "Enter") go();
    else if (e.key === "Escape") input.blur();
    else return;
    e.preventDefault();
    e.stopPropagation();
  });
  $("goto-go").addEventListener("click", () => go());
  input.addEventListener("input", () => { error.hidden = true; });
}

/**
 * Page (client) coordinates of an image point, for tests that click on the canvas.
 * @param {import("./editor.js").Editor} editor @param {number} x @param {number} y  image px
 */
export function imageToClient(editor, x, y) {
  const r = editor.canvas.getBoundingClientRect();
  const s = editor.transform.toScreen(x, y);
  return { x: r.left + s.x, y: r.top + s.y };
}

const PICK_TEXT = "Step 1 of 2: pick 2 distinctive points on the highlighted object that stay " +
  "visible most of the time (corners, printed marks), far apart. Click to place landmark 1, " +
  "then landmark 2, on this frame.";
const TRACK_TEXT = "Step 2 of 2: track both landmarks through the clip. Step through the " +
  "frames, drag a landmark where it drifts, press O while it is hidden, then Submit.";

/**
 * Runs the object task's two steps; a task whose points are all placed resumes at step 2.
 * @param {any} page
 */
export function wireObjectSteps(page) {
  const { store, editor } = page;
  const banner = $("step-banner");
  const button = /** @type {HTMLButtonElement} */ ($("start-tracking"));
  const allPicked = () => Array.from({ length: store.numPoints },
    (_, p) => store.keyframes(p).some((k) => k.x !== null)).every(Boolean);
  let step = allPicked() ? "track" : "pick";
  const show = () => {
    const locked = editor.readOnly;
    banner.hidden = locked;
    banner.dataset.step = step;
    banner.querySelector(".step-text").textContent = step === "pick" ? PICK_TEXT : TRACK_TEXT;
    button.hidden = step !== "pick";
    button.disabled = !allPicked() || locked;
    $("submit").disabled = step === "pick" || locked;
  };
  button.addEventListener("click", () => {
    step = "track";
    editor.select(0);
    show();
    button.blur();
  });
  page.refreshHooks.push(show);
  show();
}
