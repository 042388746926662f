// Money and durations as every page writes them.
import assert from "node:assert/strict";
import { test } from "node:test";

import { dollars, duration } from "../../frontend/common/format.js";

test("dollars writes the API's decimal strings with two decimals", () => {
  assert.equal(dollars("0.5"), "$0.50");
  assert.equal(dollars("12.345"), "$12.35");
  assert.equal(dollars(3), "$3.00");
  assert.equal(dollars("-1.2"), "-$1.20");
  assert.equal(dollars(""), "–");
  assert.equal(dollars(null), "–");
  assert.equal(dollars("abc"), "–");
});

test("dollars writes MTurk's amounts as USD with two decimals", () => {
  assert.equal(dollars("0.5"), "$0.50");
  assert.equal(dollars("12.00"), "$12.00");
});

test("duration writes seconds, minutes and hours for people", () => {
  assert.equal(duration(45.4), "45 s");
  assert.equal(duration(125), "2 min 05 s");
  assert.equal(duration(3720), "1 h 02 min");
  assert.equal(duration(null), "–");
  assert.equal(duration(Number.NaN), "–");
});

test("duration to the minute reads as seconds, minutes or hours and minutes", () => {
  assert.equal(duration(45, "minute"), "45 s");
  assert.equal(duration(1800, "minute"), "30 min");
  assert.equal(duration(3600, "minute"), "1 h");
  assert.equal(duration(5400, "minute"), "1 h 30 min");
});
