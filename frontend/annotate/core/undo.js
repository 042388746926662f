/**
 * Undo/redo stack of commands. A command is an object with `apply()` and `revert()`; each returns
 * a description of what it changed, which the stack hands back to its caller (the store).
 *
 * A command may also offer `mergeWith(next)`: when it returns true, `next` (already applied) has
 * been folded into it, so one drag of a point becomes one undo step instead of hundreds.
 */

/**
 * @typedef {Object} Command
 * @property {() => any} apply
 * @property {() => any} revert
 * @property {(next: Command) => boolean} [mergeWith]
 */

/** Default number of undo steps kept; older ones are dropped. */
export const DEFAULT_MAX_DEPTH = 500;

export class UndoStack {
  /** @param {number} [maxDepth] most commands kept for undo (>= 1) */
  constructor(maxDepth = DEFAULT_MAX_DEPTH) {
    if (!Number.isInteger(maxDepth) || maxDepth < 1) {
      throw new RangeError(`maxDepth must be a positive integer, got ${maxDepth}`);
    }
    this.maxDepth = maxDepth;
    /** @type {Command[]} */
    this._done = [];
    /** @type {Command[]} */
    this._undone = [];
  }

  /**
   * Applies a new command and records it. Clears the redo history.
   * @param {Command} command
   * @returns {any} what `command.apply()` returned
   */
  execute(command) {
    const result = command.apply();
    this._undone.length = 0;
    const top = this._done[this._done.length - 1];
    if (top && typeof top.mergeWith === "function" && top.mergeWith(command)) return result;
    this._done.push(command);
    if (this._done.length > this.maxDepth) this._done.splice(0, this._done.length - this.maxDepth);
    return result;
  }

  /** @returns {boolean} */
  get canUndo() {
    return this._done.length > 0;
  }

  /** @returns {boolean} */
  get canRedo() {
    return this._undone.length > 0;
  }

  /** Number of undoable steps. */
  get depth() {
    return this._done.length;
  }

  /**
   * Reverts the latest command.
   * @returns {any} what `revert()` returned, or undefined when there is nothing to undo
   */
  undo() {
    return this._move(this._done, this._undone, (command) => command.revert());
  }

  /**
   * Re-applies the latest undone command.
   * @returns {any} what `apply()` returned, or undefined when there is nothing to redo
   */
  redo() {
    return this._move(this._undone, this._done, (command) => command.apply());
  }

  /**
   * Takes the latest command off one stack, runs it one way and puts it on the other.
   * @param {Command[]} from @param {Command[]} to @param {(command: Command) => any} run
   * @returns {any} what `run` returned, or undefined when `from` is empty
   */
  _move(from, to, run) {
    const command = from.pop();
    if (!command) return undefined;
    const result = run(command);
    to.push(command);
    return result;
  }

  /** Forgets all history (after loading a saved annotation). */
  clear() {
    this._done.length = 0;
    this._undone.length = 0;
  }
}
