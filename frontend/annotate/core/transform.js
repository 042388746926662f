/**
 * The one mapping between screen coordinates (canvas CSS pixels, origin at the canvas's top-left)
 * and image coordinates (image pixels, x right, y down):
 *
 *   screen = image * scale + offset
 *
 * `scale` is screen px per image px (the zoom), clamped to [MIN_SCALE, MAX_SCALE]. Annotations
 * are always stored in image pixels; renderers call toScreen() to draw and input handlers call
 * toImage() to place. No DOM access here.
 *
 * Pixel convention: as OpenCV projects, the centre of pixel (i, j) is image coordinate (i, j), so
 * the image bitmap covers [-0.5, W - 0.5) x [-0.5, H - 0.5); imageRect() gives where to draw it.
 */

export const MIN_SCALE = 0.25;
export const MAX_SCALE = 16;

/** Distances closer than this (screen px) count as a tie in hitTest. */
const TIE_EPSILON_PX = 1e-6;

/** @param {number} s */
function clampScale(s) {
  return Math.min(Math.max(s, MIN_SCALE), MAX_SCALE);
}

export class Transform {
  /**
   * @param {number} [scale] screen px per image px
   * @param {number} [offsetX] screen x of image x = 0
   * @param {number} [offsetY] screen y of image y = 0
   */
  constructor(scale = 1, offsetX = 0, offsetY = 0) {
    this.scale = clampScale(scale);
    this.offsetX = offsetX;
    this.offsetY = offsetY;
  }

  /**
   * Screen point -> image point.
   * @param {number} sx @param {number} sy  canvas CSS px
   * @returns {{x: number, y: number}} image px
   */
  toImage(sx, sy) {
    return { x: (sx - this.offsetX) / this.scale, y: (sy - this.offsetY) / this.scale };
  }

  /**
   * Image point -> screen point.
   * @param {number} ix @param {number} iy  image px
   * @returns {{x: number, y: number}} canvas CSS px
   */
  toScreen(ix, iy) {
    return { x: ix * this.scale + this.offsetX, y: iy * this.scale + this.offsetY };
  }

  /**
   * Multiplies the zoom by `factor` (result clamped to [MIN_SCALE, MAX_SCALE]), keeping the
   * image point under the screen point (sx, sy) where it is.
   * @param {number} sx @param {number} sy  canvas CSS px, usually the cursor
   * @param {number} factor  > 1 zooms in
   */
  zoomAt(sx, sy, factor) {
    if (!(factor > 0) || !Number.isFinite(factor)) {
      throw new RangeError(`zoom factor must be a positive number, got ${factor}`);
    }
    const anchor = this.toImage(sx, sy);
    this.scale = clampScale(this.scale * factor);
    this.offsetX = sx - anchor.x * this.scale;
    this.offsetY = sy - anchor.y * this.scale;
    return this;
  }

  /**
   * Moves the image by (dx, dy) screen px.
   * @param {number} dx @param {number} dy
   */
  panBy(dx, dy) {
    this.offsetX += dx;
    this.offsetY += dy;
    return this;
  }

  /**
   * Scales the whole image to fit the canvas (within the zoom limits) and centres it.
   * @param {number} canvasW @param {number} canvasH  canvas CSS px
   * @param {number} imageW @param {number} imageH  image px
   */
  fit(canvasW, canvasH, imageW, imageH) {
    if (!(canvasW > 0 && canvasH > 0 && imageW > 0 && imageH > 0)) {
      const got = `canvas ${canvasW}x${canvasH}, image ${imageW}x${imageH}`;
      throw new RangeError(`fit needs positive sizes, got ${got}`);
    }
    this.scale = clampScale(Math.min(canvasW / imageW, canvasH / imageH));
    // Centre the bitmap, whose corner lies half a pixel before image coordinate 0.
    this.offsetX = (canvasW - imageW * this.scale) / 2 + 0.5 * this.scale;
    this.offsetY = (canvasH - imageH * this.scale) / 2 + 0.5 * this.scale;
    return this;
  }

  /**
   * Where to draw the image bitmap on screen.
   * @param {number} imageW @param {number} imageH  image px
   * @returns {{x: number, y: number, w: number, h: number}} canvas CSS px
   */
  imageRect(imageW, imageH) {
    const corner = this.toScreen(-0.5, -0.5);
    return { x: corner.x, y: corner.y, w: imageW * this.scale, h: imageH * this.scale };
  }

  /**
   * Index of the point nearest the screen point (sx, sy) within `radiusPx` screen px, or -1.
   * Never returns a farther point over a nearer one; on an exact tie the active point wins, then
   * the lower index.
   * @param {Array<{x: number|null, y: number|null}|null>} points  image px; null = not drawn
   * @param {number} sx @param {number} sy  canvas CSS px
   * @param {number} radiusPx  screen px
   * @param {number} [activeIndex]  the currently selected point, or -1
   * @returns {number}
   */
  hitTest(points, sx, sy, radiusPx, activeIndex = -1) {
    let best = -1;
    let bestDistance = Infinity;
    points.forEach((p, i) => {
      if (!p || p.x === null || p.y === null || p.x === undefined || p.y === undefined) return;
      const s = this.toScreen(p.x, p.y);
      const d = Math.hypot(s.x - sx, s.y - sy);
      if (d > radiusPx) return;
      const tie = Math.abs(d - bestDistance) <= TIE_EPSILON_PX;
      if ((!tie && d < bestDistance) || (tie && i === activeIndex)) {
        best = i;
        bestDistance = Math.min(d, bestDistance);
      }
    });
    return best;
  }
}
