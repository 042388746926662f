// Autosave: local copy until confirmed, debounce, offline retries, 409 stops, restore on reload.
import assert from "node:assert/strict";
import { test } from "node:test";

import { AnnotationStore } from "../../frontend/annotate/core/store.js";
import {
  AutoSaver, CONFLICT_TEXT, SAVE_DELAY_MS, chooseStart, localKey, readLocal,
} from "../../frontend/annotate/core/sync.js";

/** Manually advanced timers. */
class FakeTimers {
  constructor() { this.now = 0; this.queue = []; this.seq = 0; }
  setTimeout(fn, ms) { const id = ++this.seq; this.queue.push({ id, at: this.now + ms, fn }); return id; }
  clearTimeout(id) { this.queue = this.queue.filter((t) => t.id !== id); }
  async advance(ms) {
    const end = this.now + ms;
    for (;;) {
      this.queue.sort((a, b) => a.at - b.at);
      const next = this.queue[0];
      if (!next || next.at > end) break;
      this.queue.shift();
      this.now = next.at;
      next.fn();
      await flushPromises();
    }
    this.now = end;
    await flushPromises();
  }
}

const flushPromises = () => new Promise((r) => setImmediate(r));

class MemoryStorage {
  constructor() { this.items = new Map(); }
  getItem(k) { return this.items.has(k) ? this.items.get(k) : null; }
  setItem(k, v) { this.items.set(k, String(v)); }
  removeItem(k) { this.items.delete(k); }
}

/** A server that keeps a version and can be told to fail. */
class FakeApi {
  constructor(version = 0) { this.version = version; this.saves = []; this.fail = null; }
  async saveTracks(body) {
    if (this.fail === "offline") throw Object.assign(new Error("offline"), { status: 0, retryable: true });
    if (body.version !== this.version) {
      throw Object.assign(new Error("stale"), { status: 409, retryable: false });
    }
    this.saves.push(body);
    this.version += 1;
    return { version: this.version };
  }
}

function setup({ version = 0, restoredUnsaved = 0, tracks = [] } = {}) {
  const store = AnnotationStore.fromJSON({ version, tracks },
    { numPoints: 3, numFrames: 10, width: 640, height: 480 });
  const api = new FakeApi(version);
  const storage = new MemoryStorage();
  const timers = new FakeTimers();
  const statuses = [];
  const saver = new AutoSaver({ store, api, storage, key: localKey(7), timers,
    clock: { seconds: () => 12.5 }, baseEditCount: 4, restoredUnsaved,
    onStatus: (s) => statuses.push(s) });
  return { store, api, storage, timers, saver, statuses };
}

test("an edit is kept locally at once and saved within the delay", async () => {
  const { store, api, storage, timers, saver } = setup();
  store.placePoint(0, 2, 10, 20);
  const local = readLocal(storage, localKey(7));
  assert.equal(local.baseVersion, 0);
  assert.deepEqual(local.tracks[0].keyframes, [[2, 10, 20, 1]]);
  assert.equal(saver.status.message, "1 change not saved yet");
  await timers.advance(SAVE_DELAY_MS - 1);
  assert.equal(api.saves.length, 0);
  await timers.advance(1);
  assert.equal(api.saves.length, 1);
  assert.deepEqual(api.saves[0], { version: 0, tracks: store.toJSON().tracks, edit_count: 5,
    working_time_s: 12.5 });
  assert.equal(store.version, 1);
  assert.equal(saver.status.message, "All changes saved");
  assert.equal(storage.getItem(localKey(7)), null, "confirmed work leaves localStorage");
});

test("a burst of edits is one save no later than the delay after the first", async () => {
  const { store, api, timers } = setup();
  store.placePoint(0, 0, 1, 1);
  await timers.advance(SAVE_DELAY_MS / 2);
  store.placePoint(1, 0, 2, 2);
  await timers.advance(SAVE_DELAY_MS / 2);
  assert.equal(api.saves.length, 1);
  assert.equal(api.saves[0].tracks[1].keyframes.length, 1);
});

test("offline saves retry with backoff and flush when the network returns", async () => {
  const { store, api, storage, timers, saver } = setup();
  api.fail = "offline";
  store.placePoint(0, 0, 5, 5);
  await timers.advance(SAVE_DELAY_MS);
  assert.equal(saver.status.state, "offline");
  assert.match(saver.status.message, /^1 change not saved yet/);
  store.placePoint(0, 1, 6, 6);
  await timers.advance(60000);
  assert.equal(api.saves.length, 0);
  assert.equal(readLocal(storage, localKey(7)).unsaved, 2);
  api.fail = null;
  await saver.flush();
  await timers.advance(0);
  assert.equal(api.saves.length, 1);
  assert.equal(api.saves[0].tracks[0].keyframes.length, 2);
  assert.equal(saver.status.message, "All changes saved");
  assert.equal(storage.getItem(localKey(7)), null);
});

test("a stale version (409) stops saving and says another tab changed the assignment", async () => {
  const { store, api, storage, timers, saver } = setup();
  api.version = 3;
  store.placePoint(0, 0, 5, 5);
  await timers.advance(SAVE_DELAY_MS);
  assert.equal(saver.status.state, "conflict");
  assert.equal(saver.status.message, CONFLICT_TEXT);
  assert.ok(saver.stopped);
  store.placePoint(0, 1, 5, 5);
  await timers.advance(60000);
  assert.equal(api.saves.length, 0);
  assert.ok(readLocal(storage, localKey(7)), "the local copy is kept");
});

test("edits made while a save is in flight are saved next", async () => {
  const { store, api, timers } = setup();
  let release;
  const original = api.saveTracks.bind(api);
  api.saveTracks = (body) => new Promise((r) => { release = () => r(original(body)); });
  store.placePoint(0, 0, 5, 5);
  await timers.advance(SAVE_DELAY_MS);
  store.placePoint(0, 3, 9, 9);
  release();
  await timers.advance(0);
  api.saveTracks = original;
  await timers.advance(SAVE_DELAY_MS);
  assert.equal(api.saves.length, 2);
  assert.equal(api.saves[1].version, 1);
  assert.equal(api.saves[1].tracks[0].keyframes.length, 2);
});

test("restored unsaved work is saved right away", async () => {
  const tracks = [{ point: 0, keyframes: [[0, 1, 2, 1]] }];
  const { api, timers, saver } = setup({ version: 2, restoredUnsaved: 3, tracks });
  assert.equal(saver.status.message, "3 changes not saved yet");
  await timers.advance(0);
  assert.equal(api.saves.length, 1);
  assert.deepEqual(api.saves[0].tracks[0].keyframes, [[0, 1, 2, 1]]);
});

test("hold waits for the save in flight and pauses autosave until release", async () => {
  const { store, api, timers, saver } = setup();
  store.placePoint(0, 0, 5, 5);
  await timers.advance(SAVE_DELAY_MS);
  await saver.hold();
  store.placePoint(0, 1, 5, 5);
  await timers.advance(10000);
  assert.equal(api.saves.length, 1);
  saver.release();
  await timers.advance(0);
  assert.equal(api.saves.length, 2);
});

test("chooseStart restores only local work edited from the server's current version", () => {
  const server = { version: 4, tracks: { version: 4, tracks: [{ point: 0, keyframes: [] }] },
    edit_count: 10, working_time_s: 30 };
  const local = { baseVersion: 4, tracks: [{ point: 0, keyframes: [[1, 2, 3, 1]] }], unsaved: 2,
    editCount: 12, workingTime: 41, savedAt: 0 };
  const newer = chooseStart(server, local);
  assert.equal(newer.restored, true);
  assert.deepEqual(newer.tracks, local.tracks);
  assert.deepEqual([newer.unsaved, newer.editCount, newer.workingTime], [2, 12, 41]);
  const stale = chooseStart(server, { ...local, baseVersion: 3 });
  assert.equal(stale.restored, false);
  assert.equal(stale.staleLocal, true);
  assert.deepEqual(stale.tracks, server.tracks.tracks);
  assert.equal(chooseStart(server, null).restored, false);
  assert.equal(chooseStart(server, { ...local, tracks: server.tracks.tracks }).restored, false);
  assert.deepEqual(chooseStart(null, null).tracks, []);
});

test("readLocal treats junk in localStorage as nothing", () => {
  const storage = new MemoryStorage();
  storage.setItem("k", "{not json");
  assert.equal(readLocal(storage, "k"), null);
  storage.setItem("k", JSON.stringify({ tracks: "x" }));
  assert.equal(readLocal(storage, "k"), null);
  assert.equal(readLocal(null, "k"), null);
});
