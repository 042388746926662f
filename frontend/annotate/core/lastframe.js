/**
 * Where a tab last was in the clip, so that a reload reopens that frame: kept per assignment
 * (per task in a preview) in the tab's sessionStorage, which a reload keeps and another tab does
 * not share. Silent where the browser refuses storage (some sandboxed frames): a reload then
 * starts at frame 0. No DOM; the storage is passed in.
 */

/**
 * The storage key of a page's last frame.
 * @param {{task: {id: number}, assignment: {id: number}|null}} data  GET /api/annotate/task
 */
export function lastFrameKey(data) {
  return `dexlabel:frame:${data.assignment ? `a${data.assignment.id}` : `t${data.task.id}`}`;
}

/**
 * The frame kept under `key`, or 0 when there is none, it is not a frame of the clip, or the
 * storage refuses.
 * @param {() => Storage} storage  a getter: merely reading window.sessionStorage may throw
 * @param {string} key @param {number} numFrames
 * @returns {number}
 */
export function readLastFrame(storage, key, numFrames) {
  try {
    const kept = storage().getItem(key);
    const frame = kept === null ? 0 : Number(kept);
    return Number.isInteger(frame) && frame > 0 && frame < numFrames ? frame : 0;
  } catch {
    return 0;
  }
}

/**
 * @param {() => Storage} storage @param {string} key @param {number} frame
 */
export function writeLastFrame(storage, key, frame) {
  try {
    storage().setItem(key, String(frame));
  } catch {
    // No storage here: a reload starts at frame 0.
  }
}
