// Page parameters, bearer-only requests, and which failures are worth retrying.
import assert from "node:assert/strict";
import { test } from "node:test";

import { AnnotateApi, readPageParams } from "../../frontend/annotate/api.js";
import { ApiError } from "../../frontend/common/api.js";

test("an MTurk preview link is recognised and its parameters read", () => {
  const p = readPageParams("?task=T.sig&assignmentId=ASSIGNMENT_ID_NOT_AVAILABLE&hitId=H");
  assert.equal(p.preview, true);
  assert.equal(p.taskToken, "T.sig");
  assert.equal(p.token, null);
  const accepted = readPageParams("?token=A.sig&assignmentId=X1&turkSubmitTo=https%3A%2F%2Fm.example");
  assert.equal(accepted.preview, false);
  assert.equal(accepted.turkSubmitTo, "https://m.example");
});

test("the token is read from the address's fragment, which no request carries", () => {
  const p = readPageParams("?assignmentId=X1&workerId=W", "#token=A.sig");
  assert.equal(p.token, "A.sig");
  assert.equal(p.assignmentId, "X1");
  // The fragment wins over an older ?token= link.
  assert.equal(readPageParams("?token=OLD.sig", "#token=NEW.sig").token, "NEW.sig");
  assert.equal(readPageParams("?assignmentId=X1", "").token, null);
});

test("requests carry the token as a bearer header and never send cookies", async () => {
  const seen = [];
  const api = new AnnotateApi("tok.sig", { fetchFn: async (url, init) => {
    seen.push({ url, init });
    return { ok: true, status: 200, json: async () => ({ version: 3 }) };
  } });
  assert.deepEqual(await api.saveTracks({ version: 2, tracks: [] }), { version: 3 });
  assert.equal(seen[0].url, "/api/annotate/tracks");
  assert.equal(seen[0].init.method, "PUT");
  assert.equal(seen[0].init.headers.Authorization, "Bearer tok.sig");
  assert.equal(seen[0].init.credentials, "omit");
});

test("errors keep the server's detail; only network, timeout and 5xx are retryable", async () => {
  const failing = (status, body) => new AnnotateApi("t", { fetchFn: async () => (
    { ok: false, status, json: async () => body }) });
  const conflict = await failing(409, { error: "conflict", detail: "stale" }).getTask()
    .catch((e) => e);
  assert.ok(conflict instanceof ApiError);
  assert.equal(conflict.message, "stale");
  assert.equal(conflict.retryable, false);
  assert.equal((await failing(503, null).getTask().catch((e) => e)).retryable, true);
  const offline = new AnnotateApi("t", { fetchFn: async () => { throw new TypeError("Failed to fetch"); } });
  const err = await offline.getTask().catch((e) => e);
  assert.equal(err.status, 0);
  assert.equal(err.retryable, true);
});
