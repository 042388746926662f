// Screen <-> image transform, zoom about the cursor, pan, fit, and hit testing.
import assert from "node:assert/strict";
import { test } from "node:test";

import { MAX_SCALE, MIN_SCALE, Transform } from "../../frontend/annotate/core/transform.js";

const close = (a, b, tol = 1e-9) => assert.ok(Math.abs(a - b) <= tol, `${a} != ${b}`);

test("screen -> image -> screen round-trips under zoom and pan", () => {
  const tf = new Transform().fit(800, 600, 640, 480).zoomAt(123, 456, 3.7).panBy(-41.5, 17.25);
  for (const [sx, sy] of [[0, 0], [799.5, 12.25], [400, 300], [-50, 900]]) {
    const image = tf.toImage(sx, sy);
    const screen = tf.toScreen(image.x, image.y);
    close(screen.x, sx);
    close(screen.y, sy);
  }
  const back = tf.toImage(...Object.values(tf.toScreen(321.25, 17.5)));
  close(back.x, 321.25);
  close(back.y, 17.5);
});

test("zoomAt keeps the image point under the cursor fixed", () => {
  const tf = new Transform().fit(1024, 768, 640, 480);
  const cursor = [700.5, 211.25];
  const under = tf.toImage(...cursor);
  for (const factor of [1.25, 2, 0.5, 10]) {
    tf.zoomAt(...cursor, factor);
    const now = tf.toImage(...cursor);
    close(now.x, under.x);
    close(now.y, under.y);
  }
});

test("zoom is clamped to 0.25x..16x, still about the cursor", () => {
  const tf = new Transform();
  const under = tf.toImage(50, 60);
  tf.zoomAt(50, 60, 1000);
  assert.equal(tf.scale, MAX_SCALE);
  close(tf.toImage(50, 60).x, under.x);
  tf.zoomAt(50, 60, 1e-6);
  assert.equal(tf.scale, MIN_SCALE);
  close(tf.toImage(50, 60).y, under.y);
  assert.throws(() => tf.zoomAt(0, 0, 0), /positive/);
});

test("panBy shifts the image by screen pixels", () => {
  const tf = new Transform(2, 10, 20);
  tf.panBy(5, -3);
  assert.deepEqual(tf.toScreen(0, 0), { x: 15, y: 17 });
  assert.deepEqual(tf.toImage(17, 19), { x: 1, y: 1 });
});

test("fit scales the image into the canvas and centres it", () => {
  const tf = new Transform().fit(1280, 1200, 640, 480);
  assert.equal(tf.scale, 2);
  const rect = tf.imageRect(640, 480);
  assert.deepEqual(rect, { x: 0, y: 120, w: 1280, h: 960 });
  // OpenCV convention: pixel (0, 0)'s centre is image (0, 0), half a pixel in from the corner.
  assert.deepEqual(tf.toScreen(0, 0), { x: 1, y: 121 });
});

test("hitTest picks the nearest of two close points, not the first in the list", () => {
  const tf = new Transform(4, 0, 0);
  const points = [{ x: 10, y: 10 }, { x: 11, y: 10 }];
  // Cursor 3 screen px right of point 0 and 1 px left of point 1: both within the radius.
  assert.equal(tf.hitTest(points, 43, 40, 8), 1);
  assert.equal(tf.hitTest(points, 41, 40, 8), 0);
  assert.equal(tf.hitTest(points, 100, 100, 8), -1);
});

test("hitTest breaks an exact tie in favour of the active point", () => {
  const tf = new Transform(4, 0, 0);
  const points = [{ x: 10, y: 10 }, { x: 11, y: 10 }, { x: 10.5, y: 11 }];
  // Midway between points 0 and 1 (2 screen px from each); point 2 is 4 screen px away.
  assert.equal(tf.hitTest(points, 42, 40, 8), 0);
  assert.equal(tf.hitTest(points, 42, 40, 8, 1), 1);
  assert.equal(tf.hitTest(points, 42, 40, 8, 2), 0);
});

test("hitTest skips points without a position", () => {
  const tf = new Transform();
  const points = [null, { x: null, y: null }, { x: 5, y: 5 }];
  assert.equal(tf.hitTest(points, 5, 5, 3), 2);
  assert.equal(tf.hitTest([null], 5, 5, 3), -1);
});
