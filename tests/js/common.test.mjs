// The pages' shared JSON client and notice line.
import assert from "node:assert/strict";
import { afterEach, test } from "node:test";

import { ApiError, BearerClient } from "../../frontend/common/api.js";
import { errorText, noticeLine, showFailure } from "../../frontend/common/notice.js";

/** sessionStorage as a Map. */
class MemoryStorage {
  constructor() { this.items = new Map(); }
  getItem(key) { return this.items.has(key) ? this.items.get(key) : null; }
  setItem(key, value) { this.items.set(key, String(value)); }
  removeItem(key) { this.items.delete(key); }
}

const realFetch = globalThis.fetch;
afterEach(() => { globalThis.fetch = realFetch; });

/** Answers every request with one reply, and records what was asked. */
function answer(status, body) {
  const seen = [];
  globalThis.fetch = async (url, init) => {
    seen.push({ url, init });
    const text = body === undefined ? "" : JSON.stringify(body);
    return { ok: status < 400, status, text: async () => text, json: async () => JSON.parse(text) };
  };
  return seen;
}

test("the bearer client sends its kept token, JSON, and never a cookie", async () => {
  const storage = new MemoryStorage();
  storage.setItem("k", "tok.sig");
  const seen = answer(200, { id: 3 });
  const client = new BearerClient(storage, "k", "/api");
  assert.deepEqual(await client.request("POST", "/things", { name: "a" }), { id: 3 });
  assert.equal(seen[0].url, "/api/things");
  assert.equal(seen[0].init.headers.Authorization, "Bearer tok.sig");
  assert.equal(seen[0].init.headers["Content-Type"], "application/json");
  assert.equal(seen[0].init.body, '{"name":"a"}');
  assert.equal(seen[0].init.credentials, "omit");
  answer(204, undefined);
  assert.equal(await client.request("DELETE", "/things/3"), null);
});

test("a refused request is an ApiError with the API's detail; a 401 forgets the token", async () => {
  const storage = new MemoryStorage();
  storage.setItem("k", "old.sig");
  const client = new BearerClient(storage, "k", "/api");
  answer(409, { error: "conflict", detail: "already decided" });
  const refused = await client.request("POST", "/x").catch((e) => e);
  assert.ok(refused instanceof ApiError);
  assert.equal(refused.message, "already decided");
  assert.equal(refused.code, "conflict");
  assert.equal(client.token, "old.sig");
  answer(401, null);
  const expired = await client.request("GET", "/me").catch((e) => e);
  assert.equal(expired.status, 401);
  assert.equal(expired.message, "request failed (401)");
  assert.equal(client.token, null);
  assert.equal(storage.getItem("k"), null);
});

test("a network failure reads as status 0 and is worth retrying", () => {
  const err = new ApiError(0, null);
  assert.equal(err.message, "request failed (network)");
  assert.equal(err.code, "network");
  assert.equal(err.retryable, true);
  assert.equal(new ApiError(422, { detail: "x: bad" }).retryable, false);
});

test("the notice line shows errors, and a refused sign-in sends the page to sign in", () => {
  const line = { textContent: "", className: "", hidden: true };
  let signIns = 0;
  const { notify, fail } = noticeLine(line, () => { signIns += 1; });
  notify("Saved.");
  assert.deepEqual(line, { textContent: "Saved.", className: "notice info", hidden: false });
  fail(new Error("boom"));
  assert.deepEqual(line, { textContent: "boom", className: "notice error", hidden: false });
  assert.equal(signIns, 0);
  fail(new ApiError(401, { detail: "token expired" }));
  assert.equal(signIns, 1);
  assert.equal(line.textContent, "Please sign in again.");
  notify("");
  assert.equal(line.hidden, true);
  assert.equal(errorText("plain"), "plain");
});

test("a failed action says what failed and why; a refused sign-in goes to the page", () => {
  const line = { textContent: "", className: "", hidden: true };
  const failedOver = [];
  const fail = (err) => failedOver.push(err);
  showFailure(line, "Publishing", new ApiError(409, { detail: "already published" }), fail);
  assert.deepEqual(line, { textContent: "Publishing failed (409): already published",
    className: "notice error", hidden: false });
  showFailure(line, "The bonus", new Error("offline"), fail);
  assert.equal(line.textContent, "The bonus failed: offline");
  const refused = new ApiError(401, { detail: "token expired" });
  showFailure(line, "Blocking", refused, fail);
  assert.deepEqual(failedOver, [refused]);
  assert.equal(line.textContent, "The bonus failed: offline");
});

test("a notice set across navigation survives the next one only", () => {
  const line = { textContent: "", className: "", hidden: true };
  const { notify, navigated } = noticeLine(line, () => {});
  notify("Submitted. Thank you!", "info", true);
  navigated();
  assert.equal(line.textContent, "Submitted. Thank you!");
  navigated();
  assert.equal(line.textContent, "");
  assert.equal(line.hidden, true);
});

test("signing in keeps the token; signing out forgets it even when the server is away", async () => {
  const storage = new MemoryStorage();
  const client = new BearerClient(storage, "k", "/api", { login: "/auth/token", logout: "/auth/logout" });
  const seen = answer(200, { access_token: "new.sig" });
  await client.login("a@example.org", "pw");
  assert.equal(seen[0].url, "/api/auth/token");
  assert.equal(storage.getItem("k"), "new.sig");
  globalThis.fetch = async () => { throw new TypeError("Failed to fetch"); };
  await client.logout();
  assert.equal(client.token, null);
  assert.equal(storage.getItem("k"), null);
});
