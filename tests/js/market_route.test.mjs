// The worker portal's routes: the view and id of each hash.
import assert from "node:assert/strict";
import { test } from "node:test";

import { inviteOf, parseRoute } from "../../frontend/market/core/route.js";

test("parseRoute maps each hash to its view and id", () => {
  assert.deepEqual(parseRoute(""), { view: "hits", id: null });
  assert.deepEqual(parseRoute("#/hits"), { view: "hits", id: null });
  assert.deepEqual(parseRoute("#/hits/3ABC"), { view: "preview", id: "3ABC" });
  assert.deepEqual(parseRoute("#/work/3X%2FY"), { view: "work", id: "3X/Y" });
  assert.deepEqual(parseRoute("#/earnings"), { view: "earnings", id: null });
  assert.deepEqual(parseRoute("#/nowhere"), { view: "hits", id: null });
});

test("inviteOf reads the fragment's invite, and an older link's query", () => {
  assert.equal(inviteOf("#invite=abc.DEF-1", ""), "abc.DEF-1");
  assert.equal(inviteOf("", "?invite=old-link"), "old-link");
  assert.equal(inviteOf("#invite=new", "?invite=old"), "new");
  assert.equal(inviteOf("#/hits", ""), "");
  assert.equal(inviteOf("", ""), "");
  assert.deepEqual(parseRoute("#invite=abc"), { view: "hits", id: null });
});
