// The worker portal's routes: the view and id of each hash.
import assert from "node:assert/strict";
import { test } from "node:test";

import { parseRoute } from "../../frontend/market/core/route.js";

test("parseRoute maps each hash to its view and id", () => {
  assert.deepEqual(parseRoute(""), { view: "hits", id: null });
  assert.deepEqual(parseRoute("#/hits"), { view: "hits", id: null });
  assert.deepEqual(parseRoute("#/hits/3ABC"), { view: "preview", id: "3ABC" });
  assert.deepEqual(parseRoute("#/work/3X%2FY"), { view: "work", id: "3X/Y" });
  assert.deepEqual(parseRoute("#/earnings"), { view: "earnings", id: null });
  assert.deepEqual(parseRoute("#/nowhere"), { view: "hits", id: null });
});
