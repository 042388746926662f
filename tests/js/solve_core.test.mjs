// Solve review's pure core: newest-only frame loading, slider positions, chart layouts and the
// parsing of re-run settings.
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  LatestLoader, niceTop, overlayPath, parseSettings, residualBars, seriesLines, stepFrame,
  tickPercent,
} from "../../frontend/admin/core/solve-core.js";

/** A load whose replies the test releases one by one. */
function deferredLoads() {
  /** @type {{key: string, resolve: (v: string) => void, reject: (e: Error) => void}[]} */
  const pending = [];
  const load = (/** @type {string} */ key) => new Promise((resolve, reject) => {
    pending.push({ key, resolve, reject });
  });
  return { pending, load };
}

test("frames asked for while one loads are dropped but the newest, which loads next", async () => {
  const { pending, load } = deferredLoads();
  const shown = [];
  const loader = new LatestLoader(load, (key, value) => shown.push([key, value]));
  const done = loader.request("f0");
  for (const key of ["f1", "f2", "f3"]) loader.request(key);
  assert.deepEqual(loader.started, ["f0"]);
  pending[0].resolve("picture 0");
  await new Promise((resolve) => setTimeout(resolve, 0));
  // f0's reply is not the newest: dropped; only f3 is requested after it, not f1 or f2.
  assert.deepEqual(loader.started, ["f0", "f3"]);
  pending[1].resolve("picture 3");
  await done;
  await loader.idle();
  assert.deepEqual(shown, [["f3", "picture 3"]]);
});

test("asking again for the frame on its way does not load it twice", async () => {
  const { pending, load } = deferredLoads();
  const shown = [];
  const loader = new LatestLoader(load, (key) => shown.push(key));
  loader.request("f5");
  loader.request("f6");
  loader.request("f5");
  pending[0].resolve("x");
  await loader.idle();
  assert.deepEqual(loader.started, ["f5"]);
  assert.deepEqual(shown, ["f5"]);
});

test("a cancelled loader shows nothing and reports only the newest failure", async () => {
  const { pending, load } = deferredLoads();
  const shown = [], failed = [];
  const loader = new LatestLoader(load, (key) => shown.push(key), (err) => failed.push(err));
  loader.request("a");
  loader.cancel();
  pending[0].resolve("x");
  await loader.idle();
  assert.deepEqual(shown, []);
  loader.request("b");
  pending[1].reject(new Error("404"));
  await loader.idle();
  assert.equal(failed.length, 1);
});

test("stepFrame clamps to the run's frames, or wraps for playback", () => {
  assert.equal(stepFrame(0, -1, 12), 0);
  assert.equal(stepFrame(11, 1, 12), 11);
  assert.equal(stepFrame(5, 1, 12), 6);
  assert.equal(stepFrame(11, 1, 12, true), 0);
  assert.equal(stepFrame(0, -1, 12, true), 11);
  assert.equal(stepFrame(3, 0, 0), 0);
});

test("tickPercent spreads frames from 0 to 100 % of the slider", () => {
  assert.equal(tickPercent(0, 12), 0);
  assert.equal(tickPercent(11, 12), 100);
  assert.equal(tickPercent(5.5, 12), 50);
  assert.equal(tickPercent(0, 1), 0);
});

test("overlayPath asks for the style and, only when set, the opacity", () => {
  assert.equal(overlayPath(3, 7, "0", "wireframe", null),
    "/solve-runs/3/frames/7/views/0.png?style=wireframe");
  assert.equal(overlayPath(3, 7, "cam a", "blend", 0.3),
    "/solve-runs/3/frames/7/views/cam%20a.png?style=blend&alpha=0.3");
});

test("niceTop rounds an axis up to 1, 2 or 5 times a power of ten", () => {
  assert.equal(niceTop(3.2), 5);
  assert.equal(niceTop(5), 5);
  assert.equal(niceTop(12), 20);
  assert.equal(niceTop(0.7), 1);
  assert.equal(niceTop(0), 1e-9);
});

test("residualBars draws one bar per observed joint and view, heights to scale", () => {
  const box = { width: 220, height: 120, left: 10, bottom: 10, top: 10 };
  const layout = residualBars({ a: [1, null, 4], b: [2, 3, null] }, box);
  assert.equal(layout.max, 5);
  assert.equal(layout.bars.length, 4);
  assert.equal(layout.missing, 2);
  const tall = layout.bars.find((b) => b.value === 4);
  assert.ok(tall && Math.abs(tall.h - 80) < 1e-9 && Math.abs(tall.y - 30) < 1e-9);
  // Bars of view b sit right of view a's in the same joint group.
  const [a0, b0] = layout.bars.filter((b) => b.joint === 0);
  assert.ok(b0.x > a0.x && b0.x < box.left + 200 / 3);
});

test("seriesLines places frames evenly and leaves out frames without a value", () => {
  const box = { width: 110, height: 60, left: 10, bottom: 10, top: 0 };
  const layout = seriesLines([{ name: "hand", values: [0, 5, null, 10] }], box);
  assert.equal(layout.max, 10);
  assert.deepEqual(layout.lines[0].points, [[10, 50], [43.333333333333336, 25], [110, 0]]);
  // Two identical runs differ by nothing: the axis still spans 1, the line lies on 0.
  const same = seriesLines([{ name: "hand", values: [0, 0] }], box);
  assert.equal(same.max, 1);
  assert.deepEqual(same.lines[0].points, [[10, 50], [110, 50]]);
});

test("parseSettings reads each field by its kind and names a field that does not parse", () => {
  const kinds = { w_kpt: "float", lm_iterations: "int", use_depth: "bool" };
  assert.deepEqual(parseSettings(kinds, { w_kpt: "0.5", lm_iterations: "6", use_depth: false }),
    { w_kpt: 0.5, lm_iterations: 6, use_depth: false });
  assert.throws(() => parseSettings(kinds, { lm_iterations: "2.5" }), /lm_iterations must be a whole/);
  assert.throws(() => parseSettings(kinds, { w_kpt: "" }), /w_kpt must be a number/);
  assert.throws(() => parseSettings(kinds, { w_kpt: "lots" }), /w_kpt must be a number, got "lots"/);
});
