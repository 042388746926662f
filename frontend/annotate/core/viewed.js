/**
 * Which (point, frame) cells the worker has looked at while tracking proposals are shown: fed
 * by every frame the page shows (a step, a jump, each frame of playback), with the points drawn
 * there. Enter accepts a proposal only on the frames looked at, so that accepting is a
 * judgement of what was seen, never of a whole clip unseen. No DOM.
 */

export class ViewedFrames {
  constructor() {
    /** @type {Map<number, Set<number>>} point -> frames viewed */
    this._byPoint = new Map();
  }

  /** Forgets every frame (new proposals: nothing of them has been seen yet). */
  clear() {
    this._byPoint.clear();
  }

  /**
   * Records that `frame` was shown with these points drawn.
   * @param {number} frame @param {Iterable<number>} points
   */
  mark(frame, points) {
    for (const p of points) {
      let frames = this._byPoint.get(p);
      if (!frames) this._byPoint.set(p, (frames = new Set()));
      frames.add(frame);
    }
  }

  /** @param {number} point @param {number} frame @returns {boolean} */
  has(point, frame) {
    const frames = this._byPoint.get(point);
    return Boolean(frames && frames.has(frame));
  }

  /** @param {number} point @returns {number} how many frames of the point were viewed */
  count(point) {
    const frames = this._byPoint.get(point);
    return frames ? frames.size : 0;
  }
}
