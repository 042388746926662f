/**
 * Pure logic behind the annotation page's editing tools; no DOM, tested with `node --test`.
 *
 *   finger chains     which joints move together when one joint of a finger is dragged
 *   copy pose         each point's nearest keyframe before a frame
 *   joint keys        which key picks which point (1-9, 0 = 10, Shift adds 10, W = wrist)
 *   frame input       parsing a typed frame number, with a refusal naming the clip's range
 *   object outline    whether a landmark lies on the highlighted object
 *
 * Positions are image pixels; frames are 0-based indices into the clip.
 */

/**
 * The joints that move with `joint` in a chain drag: the joint and every joint after it toward
 * the fingertip, following the task's bones ([parent, child] pairs). The root of the skeleton
 * (the wrist) has no finger of its own, so it moves alone; a point without bones moves alone.
 * @param {number[][]} skeleton  [parent, child] point indices
 * @param {number} joint
 * @returns {number[]} sorted point indices, `joint` included
 */
export function chainFrom(skeleton, joint) {
  const isChild = skeleton.some(([, child]) => child === joint);
  if (!isChild) return [joint];
  const out = new Set([joint]);
  let frontier = [joint];
  while (frontier.length > 0) {
    const next = [];
    for (const [parent, child] of skeleton) {
      if (frontier.includes(parent) && !out.has(child)) {
        out.add(child);
        next.push(child);
      }
    }
    frontier = next;
  }
  return [...out].sort((a, b) => a - b);
}

/**
 * @typedef {{frame: number, x: number|null, y: number|null, visible: boolean,
 *            source?: string}} Keyframe
 * @typedef {{point: number, from: number, x: number|null, y: number|null,
 *            visible: boolean}} CopiedValue
 */

/**
 * For each point, the values of its nearest keyframe before `frame` (the pose to copy onto
 * `frame`). Points without a keyframe before `frame`, and `skip`ped ones, are left out.
 * @param {ReadonlyArray<ReadonlyArray<Keyframe>>} tracks  keyframes per point, sorted by frame
 * @param {number} frame
 * @param {(point: number) => boolean} [skip]
 * @returns {CopiedValue[]}
 */
export function previousPose(tracks, frame, skip = () => false) {
  const out = [];
  tracks.forEach((keyframes, point) => {
    if (skip(point)) return;
    let before = null;
    for (const k of keyframes) {
      if (k.frame >= frame) break;
      before = k;
    }
    if (before) out.push({ point, from: before.frame, x: before.x, y: before.y,
      visible: before.visible });
  });
  return out;
}

/**
 * What a copy did, in words: "copied 21 points from frame 8" or "... from frames 5-8".
 * @param {CopiedValue[]} copied @param {number} frame  the frame copied onto
 */
export function copySummary(copied, frame) {
  if (copied.length === 0) return `nothing to copy: no keyframe before frame ${frame}`;
  const froms = copied.map((c) => c.from);
  const lo = Math.min(...froms);
  const hi = Math.max(...froms);
  const where = lo === hi ? `frame ${hi}` : `frames ${lo}-${hi}`;
  const n = copied.length;
  return `copied ${n} point${n === 1 ? "" : "s"} from ${where}`;
}

/**
 * The key that picks each point, as shown in the point list. Hands (21 joints, numbered 0-20
 * as in the diagram): 1-9 and 0 for joint 10, Shift+1..Shift+0 for 11-20, W for the wrist (0).
 * Other tasks: 1, 2, ... for the first, second ... point.
 * @param {string} kind  "hand" | "object"
 * @param {number} numPoints
 * @returns {string[]} per point, e.g. "1", "0", "Shift+3", "W"
 */
export function jointKeys(kind, numPoints) {
  return Array.from({ length: numPoints }, (_, p) => {
    if (kind !== "hand") return p < 9 ? String(p + 1) : "";
    if (p === 0) return "W";
    if (p <= 10) return String(p % 10);
    if (p <= 20) return `Shift+${(p - 10) % 10}`;
    return "";
  });
}

/**
 * The point a key press picks, or null.
 * @param {string} kind "hand" | "object" @param {number} numPoints
 * @param {{code: string, key: string, shiftKey: boolean}} e  a KeyboardEvent; `code` is used
 *   for digits because Shift changes `key` ("!" for Shift+1 on a US layout)
 * @returns {number|null}
 */
export function pointForKey(kind, numPoints, e) {
  const m = /^(?:Digit|Numpad)([0-9])$/.exec(e.code || "");
  let point = null;
  if (m) {
    const d = Number(m[1]);
    if (kind === "hand") point = (d === 0 ? 10 : d) + (e.shiftKey ? 10 : 0);
    else if (!e.shiftKey && d > 0) point = d - 1;
  } else if (kind === "hand" && !e.shiftKey && (e.key === "w" || e.key === "W")) {
    point = 0;
  }
  return point !== null && point < numPoints ? point : null;
}

/**
 * A typed frame number, or the reason it is refused.
 * @param {string} text @param {number} numFrames
 * @returns {{frame: number, error: null}|{frame: null, error: string}}
 */
export function parseFrame(text, numFrames) {
  const t = String(text).trim();
  const range = `frames are 0-${numFrames - 1}`;
  if (!/^\d+$/.test(t)) {
    return { frame: null, error: `"${t}" is not a frame number (${range})` };
  }
  const frame = Number(t);
  if (frame >= numFrames) {
    return { frame: null, error: `frame ${frame} is not in this clip (${range})` };
  }
  return { frame, error: null };
}

/**
 * The highlighted object's outline as a polygon (image px), from a polygon or a box; null when
 * the task has none.
 * @param {{polygon?: number[][], box?: number[]}|null|undefined} highlight
 * @returns {number[][]|null}
 */
export function outlineOf(highlight) {
  if (!highlight) return null;
  if (Array.isArray(highlight.polygon) && highlight.polygon.length >= 3) return highlight.polygon;
  if (Array.isArray(highlight.box) && highlight.box.length === 4) {
    const [x0, y0, x1, y1] = highlight.box;
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
  }
  return null;
}

/** Distance (image px) from a point to the segment a-b. */
function segmentDistance(x, y, [ax, ay], [bx, by]) {
  const dx = bx - ax;
  const dy = by - ay;
  const len2 = dx * dx + dy * dy;
  const t = len2 > 0 ? Math.min(1, Math.max(0, ((x - ax) * dx + (y - ay) * dy) / len2)) : 0;
  return Math.hypot(x - (ax + t * dx), y - (ay + t * dy));
}

/**
 * Whether (x, y) lies inside the polygon or within `tolerance` px of its edge (a corner
 * landmark sits on the outline, and the outline is a convex hull of a projected mesh).
 * @param {number[][]} polygon  [[x, y], ...] image px
 * @param {number} x @param {number} y  image px
 * @param {number} [tolerance]  image px
 */
export function onOutline(polygon, x, y, tolerance = 0) {
  let inside = false;
  for (let i = 0, j = polygon.length - 1; i < polygon.length; j = i++) {
    const [xi, yi] = polygon[i];
    const [xj, yj] = polygon[j];
    if ((yi > y) !== (yj > y) && x < xi + ((y - yi) * (xj - xi)) / (yj - yi)) inside = !inside;
  }
  if (inside) return true;
  for (let i = 0, j = polygon.length - 1; i < polygon.length; j = i++) {
    if (segmentDistance(x, y, polygon[j], polygon[i]) <= tolerance) return true;
  }
  return false;
}

/**
 * Landmark keyframes that lie off the highlighted object at the frame its outline holds for
 * (only visible keyframes with a position count: an occluded landmark may sit anywhere).
 * @param {ReadonlyArray<ReadonlyArray<Keyframe>>} tracks
 * @param {number[][]} polygon @param {number} outlineFrame @param {number} tolerance  image px
 * @returns {Array<{point: number, frame: number}>}
 */
export function offObjectLandmarks(tracks, polygon, outlineFrame, tolerance) {
  const out = [];
  tracks.forEach((keyframes, point) => {
    for (const k of keyframes) {
      if (k.frame !== outlineFrame || !k.visible || k.x === null || k.y === null) continue;
      if (!onOutline(polygon, k.x, k.y, tolerance)) out.push({ point, frame: k.frame });
    }
  });
  return out;
}
