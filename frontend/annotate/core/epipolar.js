/**
 * Epipolar lines: where a point labelled in another view can lie in this one, from the pair's
 * fundamental matrix F (x_this^T F x_other = 0, image pixels of each view), clipped to this
 * view's image. No DOM.
 */

/**
 * @typedef {{serial: string, a: number, b: number, c: number}} EpipolarLine
 *   a x + b y + c = 0 in this view's image px, a^2 + b^2 = 1
 */

/**
 * Epipolar lines in this view of one point at one frame, one per labelled view.
 * @param {Array<{serial: string, F: number[][], xy: Array<Array<number[]|null>>}>} epipolar
 * @param {number} point @param {number} frame @returns {EpipolarLine[]}
 */
export function epipolarLines(epipolar, point, frame) {
  const lines = [];
  for (const view of epipolar || []) {
    const p = view.xy && view.xy[point] ? view.xy[point][frame] : null;
    if (!p) continue;
    const [a, b, c] = view.F.map((row) => row[0] * p[0] + row[1] * p[1] + row[2]);
    const norm = Math.hypot(a, b);
    if (!(norm > 0)) continue;
    lines.push({ serial: view.serial, a: a / norm, b: b / norm, c: c / norm });
  }
  return lines;
}

/**
 * The part of a line inside the image [0, width] x [0, height], or null when it misses.
 * @param {{a: number, b: number, c: number}} line @param {number} width @param {number} height
 * @returns {number[][]|null} [[x0, y0], [x1, y1]] image px
 */
export function clipLine({ a, b, c }, width, height) {
  const hits = [];
  const inside = (x, y) => x >= -1e-9 && x <= width + 1e-9 && y >= -1e-9 && y <= height + 1e-9;
  if (Math.abs(b) > 1e-12) {
    for (const x of [0, width]) hits.push([x, -(a * x + c) / b]);
  }
  if (Math.abs(a) > 1e-12) {
    for (const y of [0, height]) hits.push([-(b * y + c) / a, y]);
  }
  const kept = hits.filter(([x, y]) => inside(x, y));
  if (kept.length < 2) return null;
  // The two hits farthest apart (a line through a corner hits it twice).
  let best = null;
  for (let i = 0; i < kept.length; i++) {
    for (let j = i + 1; j < kept.length; j++) {
      const d = Math.hypot(kept[i][0] - kept[j][0], kept[i][1] - kept[j][1]);
      if (!best || d > best.d) best = { d, ends: [kept[i], kept[j]] };
    }
  }
  return best && best.d > 0 ? best.ends : null;
}
