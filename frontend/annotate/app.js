/**
 * The annotation page: reads its token from the URL, loads the task, preloads every frame, then
 * wires the editor, point list, timeline, autosave and submit together.
 *
 * Modes: "edit" (an accepted assignment), "preview" (HIT not accepted: look, don't touch),
 * "submitted" (read-only) and "review" (an admin's read-only link to a worker's saved tracks:
 * nothing is saved or submitted, and the server refuses it too). window.__dexlabel exposes the
 * live objects and load timings to the browser tests and the benchmark.
 */

import { ApiError } from "../common/api.js";
import { $ } from "../common/dom.js";
import { AnnotateApi, readPageParams } from "./api.js";
import { startAssist } from "./assist-draw.js";
import { completionEntries } from "./core/completion.js";
import { lastFrameKey, readLastFrame, writeLastFrame } from "./core/lastframe.js";
import { loadBundle } from "./core/loader.js";
import { AnnotationStore } from "./core/store.js";
import { AutoSaver, CONFLICT_TEXT, chooseStart, localKey, readLocal } from "./core/sync.js";
import { WorkClock } from "./core/worktime.js";
import { Editor } from "./editor.js";
import { pointLabels, renderInstructions, renderShortcuts } from "./instructions.js";
import { bindKeys } from "./keys.js";
import { PointList, showBanner, showLoadProgress, showSaveStatus } from "./panels.js";
import { bindPointer } from "./pointer.js";
import { completeSubmitted, openSubmitDialog } from "./submit.js";
import { Timeline } from "./timeline.js";
import { wireControls, wireObjectSteps } from "./wiring.js";

const PREVIEW_TEXT = "Preview: accept the HIT to start annotating. You can look at the clip " +
  "and the instructions; editing and submitting are disabled.";
const SUBMITTED_TEXT = "This assignment has been submitted. Thank you! It is shown read-only.";

/**
 * The banner of a review link: whose work this is, as saved.
 * @param {{worker_id: string, external_id: string, status: string, version: number}} assignment
 */
function reviewText(assignment) {
  return `Read-only review: worker ${assignment.worker_id}'s saved labels (assignment ` +
    `${assignment.external_id}, ${assignment.status}, version ${assignment.version}). ` +
    "Nothing can be changed, saved or submitted here.";
}

/** A review link's page: the banner says so and there is no Submit button at all. */
function showReview(data) {
  document.body.dataset.mode = "review";
  $("submit").hidden = true;
  showSaveStatus($("save-status"), { state: "review", message: "Read-only review" });
  showBanner($("banner"), "warn", reviewText(data.assignment));
}

/** Load timings (performance.now(), ms since navigation) for the benchmark. */
const timings = { taskLoaded: null, firstFrame: null, allFrames: null };
window.__dexlabel = { timings, ready: false, error: null };

/** localStorage, or null where the browser refuses it (some sandboxed iframes). */
function localStorageOrNull() {
  try {
    const storage = window.localStorage;
    storage.getItem("dexlabel:probe");
    return storage;
  } catch {
    return null;
  }
}

/**
 * The bearer token: from #token=, or exchanged for a task link (?task=) once the HIT is
 * accepted; the assignment token then replaces the task link, in the address's fragment with
 * how the page completes (``params.completion``, from the start reply), so a reload reopens the
 * same assignment and completes it the same way, and no request carries the token in its URL.
 * @param {import("./api.js").PageParams} params
 */
async function resolveToken(params) {
  if (params.token) {
    keepTokenInFragment(params.token, params.completion);
    return params.token;
  }
  if (!params.taskToken) {
    const detail = "This page needs the link from your HIT (no token in the address).";
    throw new ApiError(401, { detail });
  }
  if (params.preview) return params.taskToken;
  const started = await new AnnotateApi(null).start(params);
  params.completion = started.completion;
  keepTokenInFragment(started.token, started.completion);
  return started.token;
}

/**
 * Puts the token and the completion in the address's fragment (a reload reopens the same
 * assignment) and takes the token and the task link out of the query string, which the
 * browser would send to the server.
 * @param {string} token
 * @param {import("./core/completion.js").Completion|null} completion
 */
function keepTokenInFragment(token, completion) {
  const q = new URLSearchParams(location.search);
  q.delete("task");
  q.delete("token");
  const query = q.toString();
  const hash = new URLSearchParams([["token", token], ...completionEntries(completion)]);
  history.replaceState(null, "", `${location.pathname}${query ? `?${query}` : ""}#${hash}`);
}

/** Stops everything and says why (bad link, conflict, refused token). @param {any} err */
function showFatal(err) {
  const message = err && err.status === 409
    ? CONFLICT_TEXT
    : err && (err.status === 401 || err.status === 403)
      ? `This link cannot open the task: ${err.message}`
      : `Something went wrong: ${err && err.message ? err.message : err}`;
  showBanner($("banner"), "error", message);
  window.__dexlabel.error = message;
  const loading = $("loading");
  if (!window.__dexlabel.ready) loading.querySelector(".loading-text").textContent = message;
  return message;
}

/**
 * Builds the store from the server's tracks, or from unsaved local work that is newer.
 * @param {any} data  GET /api/annotate/task
 * @param {Storage|null} storage
 */
function buildStore(data, storage) {
  const { task, assignment } = data;
  const local = data.mode === "edit" ? readLocal(storage, localKey(assignment.id)) : null;
  const start = chooseStart(assignment, local);
  const store = AnnotationStore.fromJSON(
    { version: assignment ? assignment.version : 0, tracks: start.tracks },
    { numPoints: task.point_names.length, numFrames: task.num_frames,
      width: task.width, height: task.height });
  return { store, start };
}

/** The tab's sessionStorage (core/lastframe.js: reading it may throw in a sandboxed frame). */
const tabStorage = () => window.sessionStorage;

/** Everything the page needs once the task is known. */
function buildPage(data, api, params) {
  const { task } = data;
  const storage = localStorageOrNull();
  const { store, start } = buildStore(data, storage);
  const editor = new Editor({ canvas: $("view"), task, store, onUpdate: (u) => refresh(u) });
  editor.frame = readLastFrame(tabStorage, lastFrameKey(data), task.num_frames);
  const pointList = new PointList($("point-list"), task, (p) => editor.select(p));
  const timeline = new Timeline($("timeline"), {
    numFrames: task.num_frames, colors: task.point_colors, labels: pointLabels(task),
    rowHeight: task.kind === "hand" ? 14 : 22,
    onSeek: (frame, point) => {
      if (point !== null) editor.select(point);
      editor.goto(frame);
    },
  });
  // Resume at the first point not placed yet, so a reopened task continues where it stopped.
  const firstUnplaced = task.point_names.findIndex((_, p) => store.keyframes(p).length === 0);
  editor.active = Math.max(0, firstUnplaced);
  const clock = new WorkClock({ baseSeconds: start.workingTime });
  const page = { data, api, params, task, store, editor, pointList, timeline, clock,
    saver: null, storage, start, refreshHooks: [] };
  const refresh = (u) => refreshPanels(page, u);
  timeline.setTracks(store.tracks());
  return page;
}

/** Brings the panels in line with the editor. */
function refreshPanels(page, { frame, active, tracks }) {
  const { editor, timeline, task, store } = page;
  page.pointList.update(editor.points, active);
  if (tracks) timeline.setTracks(store.tracks());
  timeline.setActive(active);
  timeline.setFrame(frame);
  if (frame !== page.savedFrame) {
    page.savedFrame = frame;
    writeLastFrame(tabStorage, lastFrameKey(page.data), frame);
  }
  $("frame-label").textContent = `Frame ${frame} / ${task.num_frames - 1}`;
  $("play").textContent = editor.playing ? "Pause" : "Play";
  const editable = !editor.readOnly;
  $("undo").disabled = !editable || !store.canUndo;
  $("redo").disabled = !editable || !store.canRedo;
  $("toggle-occluded").disabled = !editable;
  $("delete-keyframe").disabled = !editable || !store.keyframeAt(active, frame);
  for (const hook of page.refreshHooks) hook();
}

/** Starts autosave (edit mode only). */
function startSaver(page) {
  const { data, store, api } = page;
  page.saver = new AutoSaver({
    store, api, storage: page.storage, key: localKey(data.assignment.id), clock: page.clock,
    baseEditCount: page.start.editCount, restoredUnsaved: page.start.unsaved,
    onStatus: (status) => {
      const wasSaving = page.saveState === "saving";
      page.saveState = status.state;
      showSaveStatus($("save-status"), status);
      if (status.state === "conflict") stopEditing(page, CONFLICT_TEXT);
      else if (status.state === "saved" && wasSaving && page.startNotice) {
        // What the page said about the work it started from (restored here, or older than
        // another tab's save) is over once a later save of this page succeeds.
        page.startNotice = false;
        showBanner($("banner"), "info", "");
      }
    },
  });
  window.addEventListener("online", () => page.saver.flush());
  if (page.start.restored) {
    page.startNotice = true;
    showBanner($("banner"), "info", "Restored your unsaved work from this browser; saving it now.");
  } else if (page.start.staleLocal) {
    page.startNotice = true;
    showBanner($("banner"), "warn", "Unsaved work in this browser was older than the saved " +
      "version (saved from another tab); the saved version is shown.");
  }
}

/** Makes the page read-only for good, with a reason. */
function stopEditing(page, message, kind = "error") {
  page.editor.readOnly = true;
  page.editor.pause();
  page.stopped = true;
  $("submit").disabled = true;
  showBanner($("banner"), kind, message);
  page.editor.render();
  refreshPanels(page, { frame: page.editor.frame, active: page.editor.active, tracks: false });
}

/**
 * After the server accepted the submission: lock the page and hand the assignment back to its
 * crowd; where that leaves the page, a link says where to go on.
 */
function onSubmitted(page, resp) {
  stopEditing(page, "Submitted. Thank you!", "ok");
  showSaveStatus($("save-status"), { state: "saved", message: "Submitted" });
  const step = completeSubmitted(window, page.params, resp);
  if (step.action === "top" || step.action === "navigate") {
    const link = document.createElement("a");
    link.href = step.url;
    link.target = "_top";
    link.textContent = "Continue";
    showBanner($("banner"), "ok", "Submitted. Thank you!", link);
  }
}

/** Opens the submit dialog. */
function requestSubmit(page) {
  if (page.editor.readOnly || !page.saver) return;
  page.editor.pause();
  openSubmitDialog({
    dialog: $("submit-dialog"), store: page.store, saver: page.saver, api: page.api,
    task: page.task,
    show: (frame, point) => { page.editor.select(point); page.editor.goto(frame); },
    onSubmitted: (resp) => onSubmitted(page, resp),
    onFatal: (err) => {
      page.saver.dispose();
      stopEditing(page, err.status === 409 ? CONFLICT_TEXT : showFatal(err));
    },
  });
}

/** Canvas input, keys, buttons, resize and working-time hooks. */
function wireInput(page) {
  const { editor, clock } = page;
  const activity = () => clock.activity();
  const keys = bindKeys(editor, {
    toggleShortcuts: () => {
      const d = $("shortcuts");
      if (d.open) d.close();
      else d.showModal();
    },
    closeOverlays: () => [...document.querySelectorAll("dialog[open]")]
      .map((d) => d.close()).length > 0,
    onActivity: activity,
  });
  bindPointer(editor, { spaceHeld: keys.spaceHeld, onPan: keys.notePan, onActivity: activity });
  document.addEventListener("visibilitychange",
    () => clock.setVisible(document.visibilityState === "visible"));
  wireControls(page, { requestSubmit: () => requestSubmit(page) });
  new ResizeObserver(() => {
    editor.resize();
    page.timeline.resize();
  }).observe($("stage"));
  editor.resize();
}

/**
 * Starts fetching the frames at once (before the page is built); the page hooks in later.
 * @param {string} url
 */
function startPreload(url) {
  const sink = { bitmaps: [], onFrame: null, onProgress: null };
  const done = loadBundle(url, {
    onProgress: (p) => sink.onProgress && sink.onProgress(p),
    onFrame: (index, bitmap) => {
      sink.bitmaps[index] = bitmap;
      if (sink.onFrame) sink.onFrame(index);
    },
  });
  return { sink, done };
}

/** Shows the current frame as soon as it is decoded; resolves when every frame is. */
async function preload(page, loading) {
  const { editor } = page;
  const overlay = $("loading");
  const showIfCurrent = (index) => {
    if (index !== editor.frame) return;
    editor.render();
    if (timings.firstFrame === null) timings.firstFrame = performance.now();
  };
  editor.bitmaps = loading.sink.bitmaps;
  loading.sink.onProgress = (p) => showLoadProgress(overlay, p);
  loading.sink.onFrame = showIfCurrent;
  if (editor.bitmaps[editor.frame]) showIfCurrent(editor.frame);
  editor.bitmaps = (await loading.done).bitmaps;
  timings.allFrames = performance.now();
  overlay.hidden = true;
}

/** Enables what the mode allows once the frames are in. */
function enterMode(page) {
  const { data, editor } = page;
  if (data.mode === "preview") showBanner($("banner"), "warn", PREVIEW_TEXT);
  else if (data.mode === "submitted") showBanner($("banner"), "ok", SUBMITTED_TEXT);
  else if (data.mode === "review") showReview(data);
  else if (!page.stopped) {
    editor.readOnly = false;
    $("submit").disabled = false;
    if (page.task.kind === "object") wireObjectSteps(page);
  }
  editor.render();
  refreshPanels(page, { frame: editor.frame, active: editor.active, tracks: true });
}

/**
 * The header's line: "Right hand: 21 joints · camera 3 of 8 · 72 frames". A view is named by
 * its place among the sequence's cameras; its serial only in the tooltip.
 * @param {any} task
 */
function taskTitle(task) {
  const target = task.target ? task.target.charAt(0).toUpperCase() + task.target.slice(1)
    : (task.kind === "hand" ? "Hand" : "Object");
  const what = task.kind === "hand" ? "21 joints" : "2 landmarks";
  return `${target}: ${what} · camera ${task.view_number} of ${task.num_views} · ` +
    `${task.num_frames} frames`;
}

async function main() {
  const params = readPageParams(location.search, location.hash);
  let data;
  let api;
  try {
    api = new AnnotateApi(await resolveToken(params));
    data = await api.getTask();
  } catch (err) {
    showFatal(err);
    return;
  }
  timings.taskLoaded = performance.now();
  const loading = startPreload(data.frames.bundle_url);
  $("task-title").textContent = taskTitle(data.task);
  $("task-title").title = `camera serial ${data.task.serial}`;
  renderInstructions($("instructions"), data.task);
  renderShortcuts($("shortcut-list"));
  const page = buildPage(data, api, params);
  Object.assign(window.__dexlabel, { page, editor: page.editor, store: page.store });
  if (data.mode === "review") showReview(data);
  wireInput(page);
  page.assist = startAssist(page);
  window.__dexlabel.assist = page.assist;
  if (data.mode === "edit") {
    startSaver(page);
    page.assist.loadSuggestions();
  }
  window.__dexlabel.saver = page.saver;
  try {
    await preload(page, loading);
  } catch (err) {
    showFatal(err);
    return;
  }
  enterMode(page);
  // The keys (arrows, shortcuts) work at once, without a click on the image first.
  $("view").focus({ preventScroll: true });
  window.__dexlabel.ready = true;
}

main();
