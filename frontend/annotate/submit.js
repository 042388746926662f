/**
 * Submitting: check the work (core/checks.js: completeness and suspicious tracks, then the
 * stretches between keyframes against the view's images, from the server), say what is
 * missing frame by frame, and only then send it. Incomplete work cannot be submitted; suspicious work needs the
 * worker to confirm. After the server accepts it, the assignment is handed back the way its
 * crowd expects (core/completion.js): MTurk's externalSubmit form, Prolific's completion link,
 * the portal's list.
 */

import { postCompletionForm, sendCompletionForm } from "./api.js";
import { checkWork, imageWarnings } from "./core/checks.js";
import { SUBMITTED_MESSAGE, completionStep } from "./core/completion.js";
import { displayName, escapeHtml } from "./instructions.js";

/** @param {import("./core/checks.js").FrameProblem} p @param {string[]} names */
function frameProblemText(p, names) {
  const frames = p.from === p.to ? `Frame ${p.from}` : `Frames ${p.from}–${p.to}`;
  const who = p.points.length === names.length
    ? `all ${names.length} points`
    : p.points.map((i) => displayName(names[i])).join(", ");
  return `${frames}: ${who} not placed or marked occluded`;
}

/**
 * @typedef {Object} SubmitContext
 * @property {HTMLDialogElement} dialog
 * @property {import("./core/store.js").AnnotationStore} store
 * @property {import("./core/sync.js").AutoSaver} saver
 * @property {import("./api.js").AnnotateApi} api
 * @property {{num_frames: number, point_names: string[]}} task
 * @property {(frame: number, point: number) => void} show   go to a problem
 * @property {(resp: {version: number}) => void} onSubmitted
 * @property {(err: Error) => void} onFatal   a conflict or refused token: stop editing
 */

/**
 * Opens the submit dialog with the check results.
 * @param {SubmitContext} ctx
 */
export function openSubmitDialog(ctx) {
  const { dialog, task } = ctx;
  const check = checkWork(ctx.store, task);
  const problemList = dialog.querySelector(".submit-problems");
  const warningList = dialog.querySelector(".submit-warnings");
  const confirmBox = dialog.querySelector(".confirm-warnings input");
  const button = dialog.querySelector(".submit-confirm");
  dialog.querySelector(".submit-summary").textContent = check.complete
    ? "Every point is placed or marked occluded in every frame."
    : "Not ready yet: every frame of every point must be placed or marked occluded.";
  problemList.innerHTML = check.byFrame.map((p, i) =>
    `<li><button type="button" data-index="${i}">` +
    `${escapeHtml(frameProblemText(p, task.point_names))}</button></li>`).join("");
  problemList.onclick = (e) => {
    const item = e.target instanceof Element ? e.target.closest("button[data-index]") : null;
    if (!item) return;
    const p = check.byFrame[Number(item.dataset.index)];
    dialog.close();
    ctx.show(p.from, p.points[0]);
  };
  const update = () => {
    button.disabled = !check.complete || (check.warnings.length > 0 && !confirmBox.checked);
  };
  const renderWarnings = () => {
    warningList.innerHTML = check.warnings.map((w) =>
      `<li>Please check: ${escapeHtml(w.message)}</li>`).join("");
    confirmBox.closest("label").hidden = check.warnings.length === 0;
    update();
  };
  confirmBox.checked = false;
  confirmBox.onchange = update;
  renderWarnings();
  // The image check is advice: a failed request leaves the local checks as they are. The
  // dialog says when it has its answer (data-image-check), for whoever waits on it.
  dialog.dataset.imageCheck = "pending";
  ctx.api.stretches({ tracks: ctx.saver.body().tracks }).then((reply) => {
    dialog.dataset.imageCheck = "done";
    const found = imageWarnings(reply);
    if (!dialog.open || found.length === 0) return;
    check.warnings.push(...found);
    confirmBox.checked = false;
    renderWarnings();
  }, () => { dialog.dataset.imageCheck = "done"; });
  setError(dialog, "");
  button.onclick = () => submitNow(ctx);
  dialog.showModal();
}

/** @param {HTMLDialogElement} dialog @param {string} message */
function setError(dialog, message) {
  const el = dialog.querySelector(".submit-error");
  el.textContent = message;
  el.hidden = !message;
}

/**
 * Sends the submit: the same body as an autosave, after any save in flight has landed.
 * @param {SubmitContext} ctx
 */
export async function submitNow(ctx) {
  const { dialog, saver, store } = ctx;
  const button = dialog.querySelector(".submit-confirm");
  button.disabled = true;
  setError(dialog, "");
  await saver.hold();
  try {
    const resp = await ctx.api.submit(saver.body());
    store.markSaved(resp.version, store.editCount);
    saver.clearLocal();
    saver.dispose();
    dialog.close();
    ctx.onSubmitted(resp);
  } catch (err) {
    handleSubmitError(ctx, err);
  }
}

/** @param {SubmitContext} ctx @param {any} err */
function handleSubmitError(ctx, err) {
  const { dialog, saver } = ctx;
  if (err.status === 409 || err.status === 401 || err.status === 403) {
    dialog.close();
    ctx.onFatal(err);
    return;
  }
  saver.release();
  dialog.querySelector(".submit-confirm").disabled = false;
  if (err.status === 0) {
    setError(dialog, "Could not reach the server. Your work is kept in this browser; " +
      "try again when you are back online.");
    return;
  }
  const problems = err.body && Array.isArray(err.body.problems) ? err.body.problems : [];
  const lines = problems.map((p) => (typeof p === "string" ? p : p.message || JSON.stringify(p)));
  setError(dialog, [`The server did not accept the submission: ${err.message}`, ...lines]
    .join("\n"));
}

/**
 * Hands a submitted assignment back to its crowd (after the server accepted the submission).
 * A framed page that may not navigate the whole window (the frame's sandbox wants the worker's
 * click, and the save took too long) goes to the url in its frame instead. A portal
 * completion first sends the marketplace's form in the background (``handIn``).
 * @param {Window} win  the page's window
 * @param {import("./api.js").PageParams} params
 * @param {{version: number}} resp  the submit reply
 * @returns {import("./core/completion.js").CompletionStep} the step taken
 */
export function completeSubmitted(win, params, resp) {
  const step = completionStep(params, { framed: win.top !== win, base: win.location.href });
  const result = `submitted:${resp.version}`;
  const go = () => takeStep(win, params, step, result);
  if ("handIn" in step && step.handIn) {
    sendCompletionForm(win.fetch.bind(win), step.handIn.url, step.handIn.assignmentId, result)
      .finally(go);
  } else {
    go();
  }
  return step;
}

/**
 * @param {Window} win @param {import("./api.js").PageParams} params
 * @param {import("./core/completion.js").CompletionStep} step @param {string} result
 */
function takeStep(win, params, step, result) {
  if (step.action === "form") {
    postCompletionForm(win.document, step.url, step.assignmentId, result);
  } else if (step.action === "parent") {
    win.parent.postMessage({ type: SUBMITTED_MESSAGE, assignmentId: params.assignmentId },
      step.origin);
  } else if (step.action === "navigate") {
    win.location.assign(step.url);
  } else if (step.action === "top") {
    try {
      /** @type {Window} */ (win.top).location.href = step.url;
    } catch {
      win.location.assign(step.url);
    }
  }
}
