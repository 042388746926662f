/**
 * Draws one frame of the annotation canvas: the image, the object highlight (object tasks), the
 * skeleton in finger colours (hand tasks) and every point in its state for this frame:
 *
 *   keyframe      filled disc             interpolated   hollow ring
 *   occluded      dashed ring with an x   not placed     not drawn
 *
 * The active point gets a halo and its name; a locked point a small padlock. Points are stored
 * in image pixels; everything is mapped through the one Transform. Marker sizes are in screen
 * pixels so they stay clickable at any zoom. Stateless: the caller passes everything in.
 */

/** Marker radius, screen px. */
export const POINT_RADIUS_PX = 5;
/** Radius of the active point's halo, screen px. */
const HALO_RADIUS_PX = 10;
const OUTLINE = "rgba(0, 0, 0, 0.85)";

/**
 * @typedef {import("./core/interpolate.js").DenseValue} DenseValue
 * @typedef {import("./core/transform.js").Transform} Transform
 * @typedef {Object} Scene
 * @property {number} cssWidth   canvas size, CSS px
 * @property {number} cssHeight
 * @property {number} dpr        device pixels per CSS px
 * @property {ImageBitmap|HTMLCanvasElement|null} bitmap  the frame, or null while loading
 * @property {number} imageWidth  image px
 * @property {number} imageHeight
 * @property {Transform} transform
 * @property {DenseValue[]} points  per point, this frame
 * @property {string[]} colors      per point, "#rrggbb"
 * @property {string[]} names       per point
 * @property {number[][]} skeleton  [a, b] bones (hand tasks)
 * @property {number} active        active point index, or -1
 * @property {{polygon?: number[][], box?: number[]}|null} highlight  image px
 * @property {ReadonlySet<number>} [locked]  points the worker locked (drawn with a padlock)
 */

/** @type {Set<(ctx: CanvasRenderingContext2D, scene: Scene) => void>} */
const layers = new Set();

/**
 * Adds a layer drawn over the image and the skeleton, under the points (assistance: ghosts,
 * epipolar lines). @param {(ctx: CanvasRenderingContext2D, scene: Scene) => void} draw
 * @returns {() => void} removes it
 */
export function addSceneLayer(draw) {
  layers.add(draw);
  return () => layers.delete(draw);
}

/**
 * Renders the whole scene.
 * @param {CanvasRenderingContext2D} ctx
 * @param {Scene} scene
 */
export function drawScene(ctx, scene) {
  ctx.setTransform(scene.dpr, 0, 0, scene.dpr, 0, 0);
  ctx.fillStyle = "#1b1f24";
  ctx.fillRect(0, 0, scene.cssWidth, scene.cssHeight);
  if (scene.bitmap) {
    const r = scene.transform.imageRect(scene.imageWidth, scene.imageHeight);
    ctx.imageSmoothingEnabled = scene.transform.scale < 2;
    ctx.drawImage(scene.bitmap, r.x, r.y, r.w, r.h);
  }
  if (scene.highlight) drawHighlight(ctx, scene.transform, scene.highlight);
  drawSkeleton(ctx, scene);
  for (const draw of layers) draw(ctx, scene);
  scene.points.forEach((value, i) => {
    if (i !== scene.active) drawPoint(ctx, scene.transform, value, scene.colors[i], false);
  });
  const active = scene.points[scene.active];
  if (active) {
    drawPoint(ctx, scene.transform, active, scene.colors[scene.active], true);
    drawLabel(ctx, scene.transform, active, scene.names[scene.active]);
  }
  for (const i of scene.locked || []) drawLockMark(ctx, scene.transform, scene.points[i]);
}

/**
 * The object to annotate, outlined so workers pick landmarks on the right one.
 * @param {CanvasRenderingContext2D} ctx @param {Transform} tf
 * @param {{polygon?: number[][], box?: number[]}} highlight  image px
 */
export function drawHighlight(ctx, tf, highlight) {
  let corners = null;
  if (Array.isArray(highlight.polygon) && highlight.polygon.length >= 3) {
    corners = highlight.polygon;
  } else if (Array.isArray(highlight.box) && highlight.box.length === 4) {
    const [x0, y0, x1, y1] = highlight.box;
    corners = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
  }
  if (!corners) return;
  traceImagePath(ctx, tf, corners);
  ctx.closePath();
  ctx.fillStyle = "rgba(255, 214, 10, 0.12)";
  ctx.fill();
  ctx.setLineDash([8, 5]);
  ctx.lineWidth = 2;
  ctx.strokeStyle = "rgba(255, 214, 10, 0.95)";
  ctx.stroke();
  ctx.setLineDash([]);
}

/**
 * Begins a path through points given in image pixels, drawn in screen pixels; the caller
 * strokes or fills it.
 * @param {CanvasRenderingContext2D} ctx @param {Transform} tf @param {number[][]} points  image px
 */
export function traceImagePath(ctx, tf, points) {
  ctx.beginPath();
  points.forEach(([x, y], i) => {
    const s = tf.toScreen(x, y);
    if (i === 0) ctx.moveTo(s.x, s.y);
    else ctx.lineTo(s.x, s.y);
  });
}

/** @param {DenseValue|undefined} v */
function placed(v) {
  return Boolean(v) && v.x !== null && v.y !== null;
}

/** Bones in the child joint's (finger's) colour; dashed where either end is occluded. */
function drawSkeleton(ctx, scene) {
  const tf = scene.transform;
  ctx.lineWidth = 2;
  for (const [a, b] of scene.skeleton) {
    const pa = scene.points[a];
    const pb = scene.points[b];
    if (!placed(pa) || !placed(pb)) continue;
    const sa = tf.toScreen(pa.x, pa.y);
    const sb = tf.toScreen(pb.x, pb.y);
    ctx.setLineDash(pa.visible && pb.visible ? [] : [4, 4]);
    ctx.strokeStyle = scene.colors[b];
    ctx.globalAlpha = 0.8;
    ctx.beginPath();
    ctx.moveTo(sa.x, sa.y);
    ctx.lineTo(sb.x, sb.y);
    ctx.stroke();
  }
  ctx.globalAlpha = 1;
  ctx.setLineDash([]);
}

/**
 * One point marker in its state style.
 * @param {CanvasRenderingContext2D} ctx @param {Transform} tf
 * @param {DenseValue} value @param {string} color @param {boolean} active
 */
export function drawPoint(ctx, tf, value, color, active) {
  if (!placed(value)) return;
  const s = tf.toScreen(value.x, value.y);
  const r = POINT_RADIUS_PX;
  if (active) {
    ctx.beginPath();
    ctx.arc(s.x, s.y, HALO_RADIUS_PX, 0, 2 * Math.PI);
    ctx.lineWidth = 3;
    ctx.strokeStyle = "#ffffff";
    ctx.stroke();
    ctx.lineWidth = 1;
    ctx.strokeStyle = OUTLINE;
    ctx.stroke();
  }
  ctx.beginPath();
  ctx.arc(s.x, s.y, r, 0, 2 * Math.PI);
  if (!value.visible) {
    drawOccluded(ctx, s, r, color);
  } else if (value.state === "keyframe") {
    ctx.fillStyle = color;
    ctx.fill();
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = OUTLINE;
    ctx.stroke();
  } else {
    ctx.lineWidth = 3.5;
    ctx.strokeStyle = OUTLINE;
    ctx.stroke();
    ctx.lineWidth = 2;
    ctx.strokeStyle = color;
    ctx.stroke();
  }
}

/** Dashed ring and an x: "somewhere here, but hidden". */
function drawOccluded(ctx, s, r, color) {
  ctx.setLineDash([3, 3]);
  ctx.lineWidth = 2;
  ctx.strokeStyle = color;
  ctx.stroke();
  ctx.setLineDash([]);
  const d = r * 0.6;
  ctx.beginPath();
  ctx.moveTo(s.x - d, s.y - d);
  ctx.lineTo(s.x + d, s.y + d);
  ctx.moveTo(s.x + d, s.y - d);
  ctx.lineTo(s.x - d, s.y + d);
  ctx.stroke();
}

/** The active point's name beside it. */
function drawLabel(ctx, tf, value, name) {
  if (!placed(value) || !name) return;
  const s = tf.toScreen(value.x, value.y);
  ctx.font = "12px system-ui, sans-serif";
  const w = ctx.measureText(name).width + 8;
  const x = s.x + HALO_RADIUS_PX + 4;
  const y = s.y - 9;
  ctx.fillStyle = "rgba(0, 0, 0, 0.7)";
  ctx.fillRect(x, y, w, 18);
  ctx.fillStyle = "#ffffff";
  ctx.fillText(name, x + 4, y + 13);
}

/** A small padlock at the lower right of a locked point's marker: no drag moves it. */
function drawLockMark(ctx, tf, value) {
  if (!placed(value)) return;
  const s = tf.toScreen(value.x, value.y);
  const x = s.x + POINT_RADIUS_PX;
  const y = s.y + POINT_RADIUS_PX - 1;
  ctx.beginPath();
  ctx.arc(x + 3.5, y, 2.3, Math.PI, 0);
  ctx.lineWidth = 1.5;
  ctx.strokeStyle = OUTLINE;
  ctx.stroke();
  ctx.fillStyle = "#ffd98a";
  ctx.strokeStyle = OUTLINE;
  ctx.lineWidth = 1;
  ctx.fillRect(x, y, 7, 5.5);
  ctx.strokeRect(x, y, 7, 5.5);
}
