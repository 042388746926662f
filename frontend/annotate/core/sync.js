/**
 * Autosave: every change reaches the server within SAVE_DELAY_MS, and until the server confirms
 * it the whole payload sits in localStorage, so a reload, a crash or an hour offline loses
 * nothing. Saves are versioned: a save based on a stale version gets 409 (another tab saved
 * first), and then this page stops saving rather than overwrite that work.
 *
 * Needs no DOM: storage, timers and the API are passed in (tests use fakes).
 */

/** A change is sent this long (ms) after the first unsaved edit; well inside the 2 s promise. */
export const SAVE_DELAY_MS = 800;
/** Retry delays after failed saves (ms), doubling up to the last. */
export const RETRY_DELAYS_MS = [1000, 2000, 4000, 8000, 15000, 30000];

/**
 * @typedef {Object} LocalRecord  what localStorage holds per assignment until the server confirms
 * @property {number} baseVersion   server version the tracks were edited from
 * @property {object[]} tracks      payload tracks (store.toJSON().tracks)
 * @property {number} unsaved       changes not yet confirmed
 * @property {number} editCount     total edits of the assignment
 * @property {number} workingTime   total active seconds
 * @property {number} savedAt       Date.now() of the write
 */

/**
 * @typedef {"saved"|"pending"|"saving"|"offline"|"conflict"|"error"} SaveState
 * @typedef {{state: SaveState, unsaved: number, message: string}} SaveStatus
 */

/** localStorage key of one assignment's unsaved work. @param {string|number} assignmentId */
export function localKey(assignmentId) {
  return `dexlabel:annotate:${assignmentId}`;
}

/**
 * Reads a LocalRecord; a missing, unreadable or malformed record reads as null.
 * @param {Storage|null} storage @param {string} key @returns {LocalRecord|null}
 */
export function readLocal(storage, key) {
  try {
    const record = storage ? JSON.parse(storage.getItem(key) || "null") : null;
    const ok = record && Number.isInteger(record.baseVersion) && Array.isArray(record.tracks);
    return ok ? record : null;
  } catch {
    return null;
  }
}

/**
 * Decides where work resumes: the server's saved tracks, or unsaved local work that was edited
 * from the server's current version (so it is newer). Local work based on an older version lost
 * the race to another save and is not restored over it.
 * @param {{version: number, tracks: {tracks: object[]}|null, edit_count: number,
 *          working_time_s: number}|null} server  the assignment as GET /task returns it
 * @param {LocalRecord|null} local
 * @returns {{tracks: object[], restored: boolean, staleLocal: boolean, unsaved: number,
 *            editCount: number, workingTime: number}}
 */
export function chooseStart(server, local) {
  const version = server ? server.version : 0;
  const fromServer = {
    tracks: server && server.tracks ? server.tracks.tracks : [],
    restored: false,
    staleLocal: false,
    unsaved: 0,
    editCount: server ? server.edit_count : 0,
    workingTime: server ? server.working_time_s : 0,
  };
  if (!local || local.unsaved <= 0) return fromServer;
  if (local.baseVersion !== version) {
    return { ...fromServer, staleLocal: local.baseVersion < version };
  }
  if (JSON.stringify(local.tracks) === JSON.stringify(fromServer.tracks)) return fromServer;
  return {
    tracks: local.tracks,
    restored: true,
    staleLocal: false,
    unsaved: local.unsaved,
    editCount: Math.max(local.editCount, fromServer.editCount),
    workingTime: Math.max(local.workingTime, fromServer.workingTime),
  };
}

/** @param {number} n */
export function unsavedText(n) {
  return `${n} ${n === 1 ? "change" : "changes"} not saved yet`;
}

export const CONFLICT_TEXT = "This assignment was changed in another tab — reload to continue";

export class AutoSaver {
  /**
   * @param {Object} o
   * @param {import("./store.js").AnnotationStore} o.store
   * @param {{saveTracks: (body: object) => Promise<{version: number}>}} o.api
   * @param {Storage|null} o.storage   localStorage, or null where the browser refuses it
   * @param {string} o.key             localKey(assignment id)
   * @param {{seconds: () => number}} o.clock  working time
   * @param {number} [o.baseEditCount] edits recorded before this page's store existed
   * @param {number} [o.restoredUnsaved] unsaved changes restored from localStorage
   * @param {(s: SaveStatus) => void} [o.onStatus]
   * @param {{setTimeout: Function, clearTimeout: Function}} [o.timers]
   */
  constructor(o) {
    Object.assign(this, { store: o.store, api: o.api, storage: o.storage, key: o.key });
    this.clock = o.clock;
    this.baseEditCount = o.baseEditCount || 0;
    this._restored = o.restoredUnsaved || 0;
    this.onStatus = o.onStatus || (() => {});
    this.timers = o.timers || { setTimeout: (f, ms) => setTimeout(f, ms),
      clearTimeout: (t) => clearTimeout(t) };
    this._timer = null;
    this._inFlight = null;
    this._failures = 0;
    this._stopped = false;
    this._held = false;
    /** @type {SaveStatus} */
    this.status = { state: "saved", unsaved: 0, message: "All changes saved" };
    this._unsubscribe = this.store.subscribe((change) => this._onChange(change));
    if (this._restored > 0) {
      this._writeLocal();
      this._schedule(0);
    }
    this._report();
  }

  /** Changes the server has not confirmed yet. */
  get unsaved() {
    return this._restored + this.store.editCount - this.store.savedEditCount;
  }

  /** The worker's actions on the assignment so far (for pay, QC and cost). */
  get editCount() {
    return this.baseEditCount + this.store.actionCount;
  }

  /** True after a 409 or a refused token: this page must not save again. */
  get stopped() {
    return this._stopped;
  }

  /** The body of a save or submit: every track, based on the store's version. */
  body() {
    const payload = this.store.toJSON();
    return { version: payload.version, tracks: payload.tracks, edit_count: this.editCount,
      working_time_s: this.clock.seconds() };
  }

  /** Saves now if anything is unsaved (e.g. when the network comes back). */
  flush() {
    this._failures = 0;
    if (this.unsaved > 0) this._schedule(0);
    return this._inFlight || Promise.resolve();
  }

  /**
   * Holds autosave (while a submit is under way) and waits for a save in flight to finish,
   * so that the store's version is the server's latest.
   */
  async hold() {
    this._held = true;
    this._clearTimer();
    if (this._inFlight) await this._inFlight;
  }

  /** Lets autosave run again after hold(). */
  release() {
    this._held = false;
    if (this.unsaved > 0) this._schedule(0);
  }

  /** Stops saving (after submit or when the page is torn down). */
  dispose() {
    this._clearTimer();
    this._unsubscribe();
  }

  /** Forgets the local copy once the server holds everything (after submit). */
  clearLocal() {
    try {
      if (this.storage) this.storage.removeItem(this.key);
    } catch {
      // Storage refused: nothing was kept there either.
    }
  }

  /** @param {object} change */
  _onChange(change) {
    if (change.cause === "saved") return;
    this._writeLocal();
    this._schedule(this._failures > 0 ? null : SAVE_DELAY_MS);
    this._report();
  }

  _writeLocal() {
    if (!this.storage) return;
    /** @type {LocalRecord} */
    const record = { baseVersion: this.store.version, tracks: this.store.toJSON().tracks,
      unsaved: this.unsaved, editCount: this.editCount, workingTime: this.clock.seconds(),
      savedAt: Date.now() };
    try {
      this.storage.setItem(this.key, JSON.stringify(record));
    } catch {
      // Quota or a sandbox without storage: the server copy is all we have; keep saving.
    }
  }

  /** @param {number|null} delayMs  null keeps an already planned retry */
  _schedule(delayMs) {
    if (this._stopped || this._held) return;
    if (this._timer !== null) {
      if (delayMs === null || delayMs > 0) return;
      this._clearTimer();
    }
    const ms = delayMs === null ? SAVE_DELAY_MS : delayMs;
    this._timer = this.timers.setTimeout(() => {
      this._timer = null;
      this._save();
    }, ms);
  }

  _clearTimer() {
    if (this._timer !== null) this.timers.clearTimeout(this._timer);
    this._timer = null;
  }

  _save() {
    if (this._stopped || this._held || this.unsaved <= 0) return;
    if (this._inFlight) {
      this._schedule(SAVE_DELAY_MS);
      return;
    }
    const editsAtSnapshot = this.store.editCount;
    this._setStatus("saving");
    this._inFlight = this.api.saveTracks(this.body())
      .then((resp) => this._saved(resp, editsAtSnapshot), (err) => this._failed(err))
      .finally(() => { this._inFlight = null; });
  }

  /** @param {{version: number}} resp @param {number} editsAtSnapshot */
  _saved(resp, editsAtSnapshot) {
    this._failures = 0;
    this._restored = 0;
    this.store.markSaved(resp.version, editsAtSnapshot);
    if (this.unsaved > 0) {
      this._writeLocal();
      this._schedule(SAVE_DELAY_MS);
    } else {
      this.clearLocal();
    }
    this._report();
  }

  /** @param {any} err */
  _failed(err) {
    if (err && err.status === 409) {
      this._stopped = true;
      this._setStatus("conflict", CONFLICT_TEXT);
      return;
    }
    if (err && err.retryable) {
      const delay = RETRY_DELAYS_MS[Math.min(this._failures, RETRY_DELAYS_MS.length - 1)];
      this._failures += 1;
      this._setStatus("offline", `${unsavedText(this.unsaved)} — offline, retrying`);
      this._schedule(delay);
      return;
    }
    if (err && (err.status === 401 || err.status === 403)) this._stopped = true;
    const detail = err && err.message ? err.message : String(err);
    const message = `${unsavedText(this.unsaved)} — the server refused the save: ${detail}`;
    this._setStatus("error", message);
  }

  _report() {
    if (this._stopped) return;
    if (this.unsaved <= 0) this._setStatus("saved", "All changes saved");
    else if (this._failures > 0) {
      this._setStatus("offline", `${unsavedText(this.unsaved)} — offline, retrying`);
    } else this._setStatus(this._inFlight ? "saving" : "pending");
  }

  /** @param {SaveState} state @param {string} [message] */
  _setStatus(state, message) {
    this.status = { state, unsaved: this.unsaved, message: message || unsavedText(this.unsaved) };
    this.onStatus(this.status);
  }
}
