// The worker portal's pure helpers: money, durations and the routes of its hash.
import assert from "node:assert/strict";
import { test } from "node:test";

import { duration, money, parseRoute } from "../../frontend/market/format.js";

test("money writes USD with two decimals", () => {
  assert.equal(money("0.5"), "$0.50");
  assert.equal(money("12.00"), "$12.00");
});

test("duration reads as seconds, minutes or hours and minutes", () => {
  assert.equal(duration(45), "45 s");
  assert.equal(duration(1800), "30 min");
  assert.equal(duration(3600), "1 h");
  assert.equal(duration(5400), "1 h 30 min");
});

test("parseRoute maps each hash to its view and id", () => {
  assert.deepEqual(parseRoute(""), { view: "hits", id: null });
  assert.deepEqual(parseRoute("#/hits"), { view: "hits", id: null });
  assert.deepEqual(parseRoute("#/hits/3ABC"), { view: "preview", id: "3ABC" });
  assert.deepEqual(parseRoute("#/work/3X%2FY"), { view: "work", id: "3X/Y" });
  assert.deepEqual(parseRoute("#/earnings"), { view: "earnings", id: null });
  assert.deepEqual(parseRoute("#/nowhere"), { view: "hits", id: null });
});
