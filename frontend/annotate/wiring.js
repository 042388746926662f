/**
 * Buttons of the page, and the two steps of an object task:
 *   step 1: pick 2 distinctive points on the highlighted object (placed on the current frame);
 *   step 2: track them through the clip (the same editor, 2 points).
 */

import { PLAY_FPS } from "./editor.js";

/**
 * Binds the toolbar, transport and point buttons.
 * @param {any} page  app.js's page object
 * @param {{$: (id: string) => HTMLElement, requestSubmit: () => void}} helpers
 */
export function wireControls(page, { $, requestSubmit }) {
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
  on("submit", () => requestSubmit());
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
 * @param {any} page @param {{$: (id: string) => HTMLElement}} helpers
 */
export function wireObjectSteps(page, { $ }) {
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
