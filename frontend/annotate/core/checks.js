/**
 * The checks before submit, as the dialog lists them: what is missing frame by frame
 * (completeness), what looks wrong (suspicious), and the server's image check of the stretches
 * between keyframes. No DOM.
 */

import { completeness, suspicious } from "./interpolate.js";

/**
 * @typedef {{from: number, to: number, points: number[]}} FrameProblem
 *   consecutive frames [from, to] missing the same points
 */

/**
 * Regroups per-point problems frame by frame: runs of consecutive frames with the same missing
 * points become one line ("frames 30-71: Thumb TIP, Index PIP").
 * @param {import("./interpolate.js").Problem[]} problems
 * @param {number} numFrames
 * @returns {FrameProblem[]}
 */
export function problemsByFrame(problems, numFrames) {
  const missing = Array.from({ length: numFrames }, () => []);
  for (const problem of problems) {
    for (const [a, b] of problem.frames) {
      for (let f = a; f <= b; f++) missing[f].push(problem.point);
    }
  }
  /** @type {FrameProblem[]} */
  const out = [];
  missing.forEach((points, f) => {
    if (points.length === 0) return;
    const last = out[out.length - 1];
    if (last && last.to === f - 1 && last.points.join() === points.join()) last.to = f;
    else out.push({ from: f, to: f, points });
  });
  return out;
}

/**
 * @param {import("./store.js").AnnotationStore} store
 * @param {{num_frames: number, point_names: string[]}} task
 */
export function checkWork(store, task) {
  const tracks = store.tracks();
  const { complete, problems } = completeness(tracks, task.num_frames, task.point_names);
  const warnings = suspicious(tracks, task.num_frames, task.point_names);
  return { complete, problems, warnings, byFrame: problemsByFrame(problems, task.num_frames) };
}

/**
 * The server's image check as submit warnings: one per stretch the images say the track does
 * not follow, worst first.
 * @param {{warnings?: Array<{point: number, frame: number, message: string}>}|null} reply
 * @returns {Array<{kind: string, point: number, frame: number, message: string}>}
 */
export function imageWarnings(reply) {
  return (reply?.warnings ?? []).map((w) => ({
    kind: "stretch", point: w.point, frame: w.frame,
    message: `${w.message}: add a keyframe where it turns`,
  }));
}
