/**
 * Preloads every frame of a view from its bundle (format: backend/captures/frames.py):
 *
 *   "DXLF"  uint32 version  uint32 header_length  header JSON  JPEG files back to back
 *
 * (little-endian). The response is read as a stream so the progress bar moves with the bytes,
 * and each frame is decoded (createImageBitmap) as soon as its last byte has arrived, so the
 * first frame shows long before the last one is in. Work starts only when all are decoded;
 * after that, stepping frames never waits on the network or a decoder.
 */

export const BUNDLE_MAGIC = "DXLF";
/** Frames decoded at once: in bundle order, so the first frame is not queued behind the rest. */
const DECODE_CONCURRENCY = 6;
export const BUNDLE_VERSION = 1;
const PREAMBLE_BYTES = 12;

/**
 * @typedef {{index: number, offset: number, length: number}} BundleEntry
 * @typedef {{width: number, height: number, frames: BundleEntry[]}} BundleHeader
 */

/** Incremental parser: feed it chunks, it hands back each frame's bytes once complete. */
export class BundleReader {
  /** @param {number} [expectedBytes]  Content-Length when known (avoids regrowing the buffer) */
  constructor(expectedBytes = 0) {
    this._buf = new Uint8Array(expectedBytes > 0 ? expectedBytes : 1 << 20);
    this.received = 0;
    /** @type {BundleHeader|null} */
    this.header = null;
    this._payloadStart = -1;
    this._next = 0;
  }

  /**
   * Appends a chunk; returns the frames that became complete, in bundle order.
   * @param {Uint8Array} chunk
   * @returns {Array<{index: number, bytes: Uint8Array}>}
   */
  push(chunk) {
    this._ensure(this.received + chunk.length);
    this._buf.set(chunk, this.received);
    this.received += chunk.length;
    if (!this.header) this._tryHeader();
    return this.header ? this._completeFrames() : [];
  }

  /** True when every frame listed in the header has been handed out. */
  get done() {
    return this.header !== null && this._next === this.header.frames.length;
  }

  /** @param {number} size */
  _ensure(size) {
    if (size <= this._buf.length) return;
    const grown = new Uint8Array(Math.max(size, this._buf.length * 2));
    grown.set(this._buf.subarray(0, this.received));
    this._buf = grown;
  }

  _tryHeader() {
    if (this.received < PREAMBLE_BYTES) return;
    const magic = String.fromCharCode(...this._buf.subarray(0, 4));
    if (magic !== BUNDLE_MAGIC) throw new Error("the frame bundle is malformed (bad magic)");
    const view = new DataView(this._buf.buffer, this._buf.byteOffset, PREAMBLE_BYTES);
    const version = view.getUint32(4, true);
    if (version !== BUNDLE_VERSION) throw new Error(`unsupported frame bundle version ${version}`);
    const headerLength = view.getUint32(8, true);
    if (this.received < PREAMBLE_BYTES + headerLength) return;
    const text = new TextDecoder().decode(
      this._buf.subarray(PREAMBLE_BYTES, PREAMBLE_BYTES + headerLength));
    const header = JSON.parse(text);
    if (!Array.isArray(header.frames)) throw new Error("the frame bundle header lists no frames");
    header.frames.sort((a, b) => a.offset - b.offset);
    this.header = header;
    this._payloadStart = PREAMBLE_BYTES + headerLength;
  }

  _completeFrames() {
    const out = [];
    const frames = this.header.frames;
    const available = this.received - this._payloadStart;
    while (this._next < frames.length) {
      const entry = frames[this._next];
      if (entry.offset + entry.length > available) break;
      const start = this._payloadStart + entry.offset;
      out.push({ index: entry.index, bytes: this._buf.slice(start, start + entry.length) });
      this._next += 1;
    }
    return out;
  }
}

/**
 * @typedef {Object} LoadProgress
 * @property {number} receivedBytes
 * @property {number} totalBytes    0 when the server sent no Content-Length
 * @property {number} decoded       frames decoded so far
 * @property {number} numFrames     frames in the bundle (0 until its header has arrived)
 */

/**
 * @typedef {Object} LoadOptions
 * @property {(p: LoadProgress) => void} [onProgress]
 * @property {(index: number, bitmap: ImageBitmap) => void} [onFrame]  each frame once decoded
 * @property {typeof fetch} [fetchFn]
 * @property {(blob: Blob) => Promise<ImageBitmap>} [decode]
 */

/**
 * Fetches a view's bundle and decodes every frame.
 * @param {string} url  bundle URL (it carries its own view token; no Authorization header, which
 *                      the frame endpoints would read as an admin login)
 * @param {LoadOptions} [options]
 * @returns {Promise<{header: BundleHeader, bitmaps: ImageBitmap[]}>} bitmaps indexed by frame
 */
export async function loadBundle(url, options = {}) {
  const fetchFn = options.fetchFn || ((...args) => fetch(...args));
  const decode = options.decode || ((blob) => createImageBitmap(blob));
  const resp = await fetchFn(url, { credentials: "omit" });
  if (!resp.ok) throw new Error(`frames could not be loaded (HTTP ${resp.status})`);
  const totalBytes = Number(resp.headers.get("Content-Length")) || 0;
  const reader = new BundleReader(totalBytes);
  const report = (decoded) => options.onProgress && options.onProgress({
    receivedBytes: reader.received, totalBytes, decoded,
    numFrames: reader.header ? reader.header.frames.length : 0,
  });
  const queue = new DecodeQueue(decode, (index, bitmap) => {
    if (options.onFrame) options.onFrame(index, bitmap);
    report(queue.decoded);
  });
  const stream = resp.body.getReader();
  for (;;) {
    const { done, value } = await stream.read();
    if (done) break;
    reader.push(value).forEach((frame) => queue.add(frame));
    report(queue.decoded);
  }
  if (!reader.done) throw new Error("the frame bundle ended early; reload to try again");
  return { header: reader.header, bitmaps: await queue.finished() };
}

/** Decodes frames in arrival order with at most DECODE_CONCURRENCY in flight. */
class DecodeQueue {
  /**
   * @param {(blob: Blob) => Promise<ImageBitmap>} decode
   * @param {(index: number, bitmap: ImageBitmap) => void} onFrame
   */
  constructor(decode, onFrame) {
    this._decode = decode;
    this._onFrame = onFrame;
    /** @type {Array<{index: number, bytes: Uint8Array}>} */
    this._waiting = [];
    this._running = 0;
    this.decoded = 0;
    /** @type {ImageBitmap[]} */
    this.bitmaps = [];
    this._error = null;
    this._idle = null;
  }

  /** @param {{index: number, bytes: Uint8Array}} frame */
  add(frame) {
    this._waiting.push(frame);
    this._pump();
  }

  _pump() {
    while (this._running < DECODE_CONCURRENCY && this._waiting.length > 0 && !this._error) {
      const frame = this._waiting.shift();
      this._running += 1;
      this._decode(new Blob([frame.bytes], { type: "image/jpeg" })).then((bitmap) => {
        this.bitmaps[frame.index] = bitmap;
        this.decoded += 1;
        this._onFrame(frame.index, bitmap);
      }, (err) => {
        this._error = err;
      }).finally(() => {
        this._running -= 1;
        this._pump();
      });
    }
    if (this._idle && (this._error || (this._running === 0 && this._waiting.length === 0))) {
      this._idle();
    }
  }

  /** Resolves with every bitmap once the queue has drained; rejects on a decode error. */
  async finished() {
    await new Promise((resolve) => {
      this._idle = resolve;
      this._pump();
    });
    if (this._error) {
      throw new Error(`a frame could not be decoded: ${this._error.message || this._error}`);
    }
    return this.bitmaps;
  }
}
