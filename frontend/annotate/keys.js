/**
 * Keyboard shortcuts of the annotation page (listed for workers in instructions.js SHORTCUTS).
 * Space toggles playback on release unless it was held to pan (Space+drag). Digits pick a point
 * (core/tools.js pointForKey: 1-9, 0 = 10, Shift adds 10, W = wrist on hands).
 */

import { $ } from "../common/dom.js";
import { pointForKey } from "./core/tools.js";

/**
 * @param {import("./editor.js").Editor} editor
 * @param {{toggleShortcuts: () => void, closeOverlays: () => boolean, onActivity: () => void}}
 *   hooks  closeOverlays returns true when it closed something
 * @returns {{spaceHeld: () => boolean, notePan: () => void}}
 */
export function bindKeys(editor, hooks) {
  let spaceDown = false;
  let pannedWithSpace = false;

  const typing = (e) => {
    const t = e.target;
    return t instanceof HTMLElement &&
      (t.isContentEditable || ["INPUT", "TEXTAREA", "SELECT"].includes(t.tagName));
  };

  window.addEventListener("keydown", (e) => {
    if (typing(e)) return;
    hooks.onActivity();
    if (e.key === "?") {
      hooks.toggleShortcuts();
      e.preventDefault();
      return;
    }
    if (e.key === "Escape") {
      if (hooks.closeOverlays()) e.preventDefault();
      return;
    }
    if (document.querySelector("dialog[open]")) return;
    if (e.key === " ") {
      e.preventDefault();
      if (!e.repeat) {
        spaceDown = true;
        pannedWithSpace = false;
      }
      return;
    }
    if (handleKey(editor, e)) e.preventDefault();
  });

  window.addEventListener("keyup", (e) => {
    if (e.key !== " " || !spaceDown) return;
    spaceDown = false;
    if (!pannedWithSpace && !document.querySelector("dialog[open]")) editor.togglePlay();
    e.preventDefault();
  });
  window.addEventListener("blur", () => { spaceDown = false; });

  return {
    spaceHeld: () => spaceDown,
    notePan: () => { if (spaceDown) pannedWithSpace = true; },
  };
}

/**
 * Runs the action bound to a key. @returns {boolean} whether the key was one of ours
 * @param {import("./editor.js").Editor} editor @param {KeyboardEvent} e
 */
function handleKey(editor, e) {
  const ctrl = e.ctrlKey || e.metaKey;
  const key = e.key.length === 1 ? e.key.toLowerCase() : e.key;
  if (ctrl && key === "z") return (e.shiftKey ? editor.redo() : editor.undo()) || true;
  if (ctrl && key === "y") return editor.redo() || true;
  if (ctrl || e.altKey) return false;
  const picked = pointForKey(editor.task.kind, editor.numPoints, e);
  if (picked !== null) {
    editor.select(picked);
    return true;
  }
  switch (key) {
    case "ArrowLeft": editor.step(e.shiftKey ? -10 : -1); return true;
    case "ArrowRight": editor.step(e.shiftKey ? 10 : 1); return true;
    case "Home": editor.goto(0); return true;
    case "End": editor.goto(editor.numFrames - 1); return true;
    case "[": editor.jumpKeyframe(-1); return true;
    case "]": editor.jumpKeyframe(1); return true;
    case "o": editor.toggleOccluded(); return true;
    case "n": editor.nextPoint(); return true;
    case "f": editor.fit(); return true;
    case "c": editor.copyPreviousPose(); return true;
    case "h": editor.setHidden(editor.active, !editor.hidden.has(editor.active)); return true;
    case "g": return focusFrameInput();
    case "Delete":
    case "Backspace": editor.deleteKeyframe(); return true;
    default: return false;
  }
}

/** Puts the cursor in the go-to-frame box (key G). @returns {boolean} whether there is one */
function focusFrameInput() {
  const input = $("goto-frame");
  if (!(input instanceof HTMLInputElement)) return false;
  input.focus();
  input.select();
  return true;
}
