/**
 * The worker-facing API of the annotation page.
 *
 * Identity is the signed assignment (or, in preview, task) token from the page URL, sent as a
 * Bearer header. No cookies: the page runs inside a sandboxed MTurk iframe where third-party
 * cookies are blocked.
 */

import { ApiError, jsonOrNull, requestInit } from "../common/api.js";
import { checkedCompletion, completionFromFragment } from "./core/completion.js";

/** Marketplace placeholder for an assignment that has not been accepted yet (preview). */
export const PREVIEW_ASSIGNMENT_ID = "ASSIGNMENT_ID_NOT_AVAILABLE";

/** A save or read that the network never answered gets this long (ms) before it counts as lost. */
const REQUEST_TIMEOUT_MS = 15000;

/**
 * @typedef {Object} PageParams
 * @property {string|null} token         assignment token (or task token in preview)
 * @property {string|null} taskToken     task token of an MTurk-style link (?task=)
 * @property {string|null} assignmentId
 * @property {string|null} hitId
 * @property {string|null} workerId
 * @property {string|null} turkSubmitTo
 * @property {boolean} preview           the HIT has not been accepted yet
 * @property {import("./core/completion.js").Completion|null} completion  how the page
 *   completes (the start reply's, kept in the fragment beside the token)
 */

/**
 * Reads the page's address: the marketplace's parameters from the query string, the token and
 * the completion from the fragment (#token=, never sent to a server; an older ?token= link is
 * still read).
 * @param {string} search  location.search
 * @param {string} [hash]  location.hash
 * @returns {PageParams}
 */
export function readPageParams(search, hash = "") {
  const q = new URLSearchParams(search);
  const h = new URLSearchParams(hash.replace(/^#/, ""));
  // MTurk's names (the built-in marketplace's too), else Prolific's: its submission is the
  // assignment, its study names the unit (the server finds the task's unit in it).
  const assignmentId = q.get("assignmentId") ?? q.get("SESSION_ID");
  return {
    token: h.get("token") ?? q.get("token"),
    taskToken: q.get("task"),
    assignmentId,
    hitId: q.get("hitId") ?? q.get("STUDY_ID"),
    workerId: q.get("workerId") ?? q.get("PROLIFIC_PID"),
    turkSubmitTo: q.get("turkSubmitTo"),
    preview: assignmentId === PREVIEW_ASSIGNMENT_ID,
    completion: completionFromFragment(h),
  };
}

/**
 * Runs fetch with a timeout; network failures become ApiError(0).
 * @param {typeof fetch} fetchFn @param {string} url @param {RequestInit} init
 */
async function fetchOrNetworkError(fetchFn, url, init) {
  const controller = new AbortController();
  const timer = setTimeout(() => controller.abort(), REQUEST_TIMEOUT_MS);
  try {
    return await fetchFn(url, { ...init, signal: controller.signal });
  } catch (err) {
    throw new ApiError(0, { error: "network", detail: `network error: ${err.message || err}` });
  } finally {
    clearTimeout(timer);
  }
}

export class AnnotateApi {
  /**
   * @param {string|null} token  bearer token
   * @param {{fetchFn?: typeof fetch, base?: string}} [options]
   */
  constructor(token, { fetchFn, base = "" } = {}) {
    this.token = token;
    this.base = base;
    this._fetch = fetchFn || ((...args) => fetch(...args));
  }

  /**
   * JSON request; resolves to the parsed body, rejects with ApiError.
   * @param {string} method @param {string} path @param {object} [body]
   */
  async request(method, path, body) {
    const init = requestInit(method, this.token, body);
    const resp = await fetchOrNetworkError(this._fetch, this.base + path, init);
    const data = await jsonOrNull(resp);
    if (!resp.ok) throw new ApiError(resp.status, data);
    return data;
  }

  /**
   * Exchanges an MTurk-style task link for an assignment token, and learns how the page
   * completes (null: the HIT's provider did not say; an unusable completion counts as none).
   * @param {PageParams} params
   * @returns {Promise<{token: string,
   *   completion: import("./core/completion.js").Completion|null}>}
   */
  async start(params) {
    const data = await this.request("POST", "/api/annotate/start", {
      task_token: params.taskToken,
      assignment_id: params.assignmentId,
      hit_id: params.hitId,
      worker_id: params.workerId,
    });
    return { token: data.token, completion: checkedCompletion(data.completion) };
  }

  /** The task, its frames and the assignment's saved tracks. */
  getTask() {
    return this.request("GET", "/api/annotate/task");
  }

  /**
   * Saves every track, based on `body.version`.
   * @param {{version: number, tracks: object[], edit_count: number, working_time_s: number}} body
   * @returns {Promise<{version: number}>}
   */
  saveTracks(body) {
    return this.request("PUT", "/api/annotate/tracks", body);
  }

  /**
   * Tracking proposals between keyframes (nothing is stored).
   * @param {{tracks: object[], first_frame?: number, last_frame?: number}} body  saved rows
   * @returns {Promise<{first_frame: number, last_frame: number, points: Array<{point: number,
   *   xy: Array<number[]|null>, ok: boolean[], fb_error: Array<number|null>}>}>}
   */
  proposals(body) {
    return this.request("POST", "/api/annotate/proposals", body);
  }

  /**
   * The hand model followed through the view's depth from the worker's keyframes (hand
   * tasks; nothing is stored for the assignment). While the server prepares it the answer
   * says `preparing`: ask again with the same body.
   * @param {{tracks: object[], begin?: number}} body  saved rows of the anchors
   * @returns {Promise<{available: boolean, preparing: boolean, reason: string|null,
   *   start_frame: number|null, first_frame: number, last_frame: number,
   *   points: Array<{point: number, xy: Array<number[]|null>, ok: boolean[]}>,
   *   stops: Array<{direction: string, reached: number, stopped: string}>}>}
   */
  modelFollow(body) {
    return this.request("POST", "/api/annotate/model-follow", body);
  }

  /**
   * The check before submit: stretches between keyframes the view's images say the track
   * does not follow (nothing is stored).
   * @param {{tracks: object[]}} body  saved rows
   * @returns {Promise<{tolerance_px: number, checked_frames: number, warnings: Array<{point:
   *   number, frames: number[], frame: number, offset_px: number, message: string}>}>}
   */
  stretches(body) {
    return this.request("POST", "/api/annotate/stretches", body);
  }

  /**
   * Pre-fill from the other views' accepted work, and their epipolar data.
   * @returns {Promise<{available: boolean, reason: string|null, views: number,
   *   points: object[], epipolar: object[]}>}
   */
  suggestions() {
    return this.request("GET", "/api/annotate/suggestions");
  }

  /**
   * Saves and submits (same body as saveTracks).
   * @param {{version: number, tracks: object[], edit_count: number, working_time_s: number}} body
   * @returns {Promise<{status: string, version: number}>}
   */
  submit(body) {
    return this.request("POST", "/api/annotate/submit", body);
  }
}

/**
 * Posts the marketplace's completion form (MTurk's {turkSubmitTo}/mturk/externalSubmit: the
 * action comes from core/completion.js) from the page. The labels stay in our database; the
 * marketplace only learns that the work is done.
 * @param {Document} doc
 * @param {string} action  the form's address
 * @param {string} assignmentId
 * @param {string} result
 * @returns {HTMLFormElement} the form (already submitted)
 */
export function postCompletionForm(doc, action, assignmentId, result) {
  const form = doc.createElement("form");
  form.method = "POST";
  form.action = action;
  form.hidden = true;
  for (const [name, value] of [["assignmentId", assignmentId], ["result", result]]) {
    const input = doc.createElement("input");
    input.type = "hidden";
    input.name = name;
    input.value = value;
    form.appendChild(input);
  }
  doc.body.appendChild(form);
  form.submit();
  return form;
}

/**
 * The completion form sent in the background (the page stays): resolves true when the
 * marketplace took it, false when it refused or could not be reached (the page goes on; the
 * work is saved and submitted here, and an admin sees the assignment left "working").
 * @param {typeof fetch} fetchFn @param {string} action @param {string} assignmentId
 * @param {string} result
 * @returns {Promise<boolean>}
 */
export async function sendCompletionForm(fetchFn, action, assignmentId, result) {
  try {
    const resp = await fetchFn(action, {
      method: "POST", body: new URLSearchParams({ assignmentId, result }),
      credentials: "same-origin", keepalive: true });
    return resp.ok;
  } catch {
    return false;
  }
}
