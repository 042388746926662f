// Frame bundle parsing: incremental, in any chunking, and the loader's progress and decoding.
import assert from "node:assert/strict";
import { test } from "node:test";

import { BundleReader, loadBundle } from "../../frontend/annotate/core/loader.js";

/** A bundle as backend/captures/frames.py writes it. @param {Uint8Array[]} files */
function makeBundle(files, { magic = "DXLF", version = 1 } = {}) {
  let offset = 0;
  const frames = files.map((f, index) => {
    const entry = { index, offset, length: f.length };
    offset += f.length;
    return entry;
  });
  const header = new TextEncoder().encode(JSON.stringify({ width: 4, height: 3, frames }));
  const out = new Uint8Array(12 + header.length + offset);
  out.set(new TextEncoder().encode(magic), 0);
  const view = new DataView(out.buffer);
  view.setUint32(4, version, true);
  view.setUint32(8, header.length, true);
  out.set(header, 12);
  let at = 12 + header.length;
  for (const f of files) {
    out.set(f, at);
    at += f.length;
  }
  return out;
}

const files = [[1, 2, 3], [4], [5, 6, 7, 8, 9], [10, 11]].map((a) => new Uint8Array(a));

test("every chunking of a bundle yields every frame once, in order, byte-exact", () => {
  const bundle = makeBundle(files);
  for (const size of [1, 2, 5, 13, bundle.length]) {
    const reader = new BundleReader(size === 1 ? 0 : bundle.length);
    const got = [];
    for (let i = 0; i < bundle.length; i += size) got.push(...reader.push(bundle.subarray(i, i + size)));
    assert.deepEqual(got.map((f) => f.index), [0, 1, 2, 3], `chunk ${size}`);
    got.forEach((f) => assert.deepEqual([...f.bytes], [...files[f.index]]));
    assert.ok(reader.done);
  }
});

test("a frame is handed out as soon as its last byte arrives", () => {
  const bundle = makeBundle(files);
  const reader = new BundleReader();
  const headerEnd = bundle.length - 11;
  assert.deepEqual(reader.push(bundle.subarray(0, headerEnd)), []);
  assert.deepEqual(reader.push(bundle.subarray(headerEnd, headerEnd + 3)).map((f) => f.index), [0]);
  assert.equal(reader.done, false);
});

test("a bundle with the wrong magic or version is refused with a clear error", () => {
  assert.throws(() => new BundleReader().push(makeBundle(files, { magic: "JUNK" })), /bad magic/);
  assert.throws(() => new BundleReader().push(makeBundle(files, { version: 9 })), /version 9/);
});

/** A fetch Response stand-in streaming `bytes` in `size` chunks. */
function fakeResponse(bytes, size, { ok = true, status = 200, length = true } = {}) {
  let at = 0;
  return {
    ok, status,
    headers: { get: (name) => (name === "Content-Length" && length ? String(bytes.length) : null) },
    body: { getReader: () => ({
      read: async () => {
        if (at >= bytes.length) return { done: true, value: undefined };
        const value = bytes.subarray(at, at + size);
        at += size;
        return { done: false, value };
      },
    }) },
  };
}

test("loadBundle decodes every frame and reports progress up to all frames", async () => {
  const bundle = makeBundle(files);
  const progress = [];
  const seen = [];
  const result = await loadBundle("/bundle", {
    fetchFn: async () => fakeResponse(bundle, 7),
    decode: async (blob) => ({ size: blob.size, type: blob.type }),
    onProgress: (p) => progress.push(p),
    onFrame: (i) => seen.push(i),
  });
  assert.deepEqual(result.bitmaps.map((b) => b.size), files.map((f) => f.length));
  assert.equal(result.bitmaps[0].type, "image/jpeg");
  assert.deepEqual([...seen].sort(), [0, 1, 2, 3]);
  const last = progress[progress.length - 1];
  assert.equal(last.decoded, 4);
  assert.equal(last.numFrames, 4);
  assert.equal(last.receivedBytes, bundle.length);
  assert.equal(last.totalBytes, bundle.length);
});

test("loadBundle fails clearly on an HTTP error and on a truncated bundle", async () => {
  const bundle = makeBundle(files);
  await assert.rejects(loadBundle("/b", { fetchFn: async () => fakeResponse(bundle, 5,
    { ok: false, status: 401 }) }), /HTTP 401/);
  await assert.rejects(loadBundle("/b", {
    fetchFn: async () => fakeResponse(bundle.subarray(0, bundle.length - 1), 5, { length: false }),
    decode: async () => ({}),
  }), /ended early/);
});

test("loadBundle rejects when a frame cannot be decoded", async () => {
  const bundle = makeBundle(files);
  await assert.rejects(loadBundle("/b", {
    fetchFn: async () => fakeResponse(bundle, 64),
    decode: async (blob) => {
      if (blob.size === 5) throw new Error("corrupt JPEG");
      return {};
    },
  }), /could not be decoded: corrupt JPEG/);
});
