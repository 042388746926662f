// Working time: counts while visible and recently active; idle and hidden time is not paid.
import assert from "node:assert/strict";
import { test } from "node:test";

import { WorkClock } from "../../frontend/annotate/core/worktime.js";

test("active time accrues from the base while the worker keeps going", () => {
  let now = 1000;
  const clock = new WorkClock({ baseSeconds: 5, now: () => now, idleAfterMs: 60000 });
  now += 10000;
  clock.activity();
  now += 20000;
  assert.equal(clock.seconds(), 35);
});

test("time stops counting while the tab is hidden", () => {
  let now = 0;
  const clock = new WorkClock({ now: () => now });
  now = 4000;
  clock.setVisible(false);
  now = 100000;
  assert.equal(clock.seconds(), 4);
  clock.setVisible(true);
  now = 103000;
  assert.equal(clock.seconds(), 7);
});

test("time stops counting after the idle limit without input", () => {
  let now = 0;
  const clock = new WorkClock({ now: () => now, idleAfterMs: 60000 });
  now = 10 * 60000;
  assert.equal(clock.seconds(), 60);
  clock.activity();
  now += 5000;
  assert.equal(clock.seconds(), 65);
});
