/**
 * SVG charts of solve review: one frame's reprojection error per joint and view, and the
 * per-frame differences between two runs. Thin: the layouts come from core/solve-core.js.
 */

import { HAND_JOINTS } from "./core/format.js";
import { residualBars, seriesLines } from "./core/solve-core.js";

const SVG = "http://www.w3.org/2000/svg";
/** One colour per view / series (colour-blind safe, Okabe-Ito). */
export const SERIES_COLOURS = ["#0072b2", "#e69f00", "#009e73", "#cc79a7", "#56b4e9",
  "#d55e00", "#f0e442", "#555555"];

/**
 * @param {string} tag
 * @param {Record<string, string|number>} [attrs]
 * @param {(Node|string)[]} [children]
 */
function svg(tag, attrs = {}, children = []) {
  const node = document.createElementNS(SVG, tag);
  for (const [name, value] of Object.entries(attrs)) node.setAttribute(name, String(value));
  node.append(...children);
  return node;
}

/** "W", then finger initial and joint number: "T1".."L4". @param {string} name */
function shortJoint(name) {
  if (!name.includes("_")) return name[0].toUpperCase();
  const [finger, joint] = name.split("_");
  return finger[0].toUpperCase() + String(["mcp", "pip", "dip", "tip"].indexOf(joint) + 1);
}

/**
 * @param {SVGElement} root @param {{width: number, height: number, left: number,
 *   bottom: number, top: number}} box @param {number} max @param {string} unit
 */
function yAxis(root, box, max, unit) {
  const plotH = box.height - box.top - box.bottom;
  for (const k of [0, 0.5, 1]) {
    const y = box.top + plotH * (1 - k);
    root.append(svg("line", { x1: box.left, x2: box.width, y1: y, y2: y, class: "grid" }),
      svg("text", { x: box.left - 4, y: y + 3, class: "tick end" }, [`${+(max * k).toFixed(2)}`]));
  }
  root.append(svg("text", { x: 0, y: box.top - 6, class: "tick" }, [unit]));
}

/**
 * Bars of one frame's reprojection error (px) per joint, one colour per view.
 * @param {Record<string, (number|null)[]>} errors  GET .../frames/{f} kpt_error_px
 * @param {number} frame
 */
export function residualChart(errors, frame) {
  const box = { width: 420, height: 190, left: 34, bottom: 34, top: 16 };
  const layout = residualBars(errors, box);
  const root = svg("svg", {
    viewBox: `0 0 ${box.width} ${box.height}`, role: "img", "data-chart": "residuals",
    "data-frame": frame, "data-max": layout.max, "data-bars": layout.bars.length,
    "aria-label": `reprojection error per joint and view, frame ${frame}`,
  });
  yAxis(root, box, layout.max, "px");
  const serials = Object.keys(errors);
  for (const bar of layout.bars) {
    root.append(svg("rect", {
      x: bar.x.toFixed(2), y: bar.y.toFixed(2), width: bar.w.toFixed(2), height: bar.h.toFixed(2),
      fill: SERIES_COLOURS[bar.view % SERIES_COLOURS.length], class: "bar",
    }, [svg("title", {}, [`${HAND_JOINTS[bar.joint] || bar.joint}, view ${serials[bar.view]}: `
      + `${bar.value.toFixed(1)} px`])]));
  }
  const group = (box.width - box.left) / HAND_JOINTS.length;
  HAND_JOINTS.forEach((name, j) => {
    if (j % 2) return;  // every other label: 21 of them do not fit side by side
    root.append(svg("text", { x: box.left + group * (j + 0.5), y: box.height - box.bottom + 12,
      class: "tick mid" }, [shortJoint(name)]));
  });
  serials.forEach((serial, v) => {
    const x = box.left + 92 * v;
    root.append(svg("rect", { x, y: box.height - 12, width: 9, height: 9,
      fill: SERIES_COLOURS[v % SERIES_COLOURS.length] }),
    svg("text", { x: x + 12, y: box.height - 4, class: "tick" }, [serial.slice(0, 12)]));
  });
  if (!layout.bars.length) {
    root.append(svg("text", { x: box.width / 2, y: box.height / 2, class: "tick mid" },
      ["no joint observed in this frame"]));
  }
  return root;
}

/**
 * Lines of per-frame differences between two runs on one axis, with a legend.
 * @param {{name: string, values: (number|null)[]}[]} series
 * @param {string} unit
 * @param {number|null} [marked]  a frame to mark with a vertical line
 */
export function differenceChart(series, unit, marked = null) {
  const box = { width: 640, height: 200, left: 40, bottom: 40, top: 16, right: 12 };
  const layout = seriesLines(series, box);
  const root = svg("svg", { viewBox: `0 0 ${box.width} ${box.height}`, role: "img",
    "data-chart": "compare", "data-max": layout.max,
    "aria-label": `difference per frame between the two runs (${unit})` });
  yAxis(root, box, layout.max, unit);
  const count = Math.max(0, ...series.map((s) => s.values.length));
  const every = Math.max(1, Math.ceil(count / 12));
  for (let f = 0; f < count; f += every) {
    root.append(svg("text", { x: layout.x(f), y: box.height - box.bottom + 12,
      class: "tick mid" }, [String(f)]));
  }
  if (marked !== null) {
    root.append(svg("line", { x1: layout.x(marked), x2: layout.x(marked), y1: box.top,
      y2: box.height - box.bottom, class: "marker" }));
  }
  layout.lines.forEach((line, k) => {
    const colour = SERIES_COLOURS[k % SERIES_COLOURS.length];
    root.append(svg("polyline", { points: line.points.map((p) => p.join(",")).join(" "),
      fill: "none", stroke: colour, "stroke-width": 2, "data-series": line.name }));
    for (const [x, y] of line.points) root.append(svg("circle", { cx: x, cy: y, r: 2.5, fill: colour }));
    const lx = box.left + 150 * k;
    root.append(svg("rect", { x: lx, y: box.height - 12, width: 9, height: 9, fill: colour }),
      svg("text", { x: lx + 12, y: box.height - 4, class: "tick" }, [line.name]));
  });
  return root;
}
