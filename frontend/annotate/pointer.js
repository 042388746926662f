/**
 * Mouse and pen input on the annotation canvas:
 *
 *   click on empty image        places the active point here (this frame)
 *   click on a point            selects it, except while the active point has no position in
 *                               this frame: then the click places it (joints of a small hand lie
 *                               within a marker's width of each other, and placing must not turn
 *                               into selecting a neighbour)
 *   drag a point                moves the point under the cursor, the nearest one: never a
 *                               neighbour (Transform.hitTest), and it does not jump to the cursor
 *   Shift+drag a point          moves the whole skeleton (every unlocked placed point)
 *   Alt+drag or Ctrl+drag       moves the point and the joints after it toward the fingertip
 *                               (both, as some desktops take Alt+drag for moving windows and
 *                               macOS takes Ctrl+click for the context menu, refused here)
 *   hidden points               cannot be grabbed; locked ones are not moved by any drag
 *   right/middle drag, Space+drag   pans; wheel zooms about the cursor
 *
 * A drag is one undo step (a gesture id shared by its edits), a group drag included.
 */

/** A press within this distance (screen px) of a point grabs it. */
export const HIT_RADIUS_PX = 10;
/** Movement (screen px) below which a press-release is a click. */
const CLICK_SLOP_PX = 4;

/**
 * @param {import("./editor.js").Editor} editor
 * @param {{spaceHeld: () => boolean, onPan: () => void, onActivity: () => void}} hooks
 *   spaceHeld: whether Space is down (Space+drag pans); onPan: a pan happened (so releasing
 *   Space does not toggle playback); onActivity: any input (working time)
 * @returns {CanvasPointer}
 */
export function bindPointer(editor, hooks) {
  const pointer = new CanvasPointer(editor, hooks);
  const canvas = editor.canvas;
  canvas.addEventListener("pointerdown", (e) => pointer.down(e));
  canvas.addEventListener("pointermove", (e) => pointer.move(e));
  canvas.addEventListener("pointerup", (e) => pointer.up(e, false));
  canvas.addEventListener("pointercancel", (e) => pointer.up(e, true));
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("wheel", (e) => pointer.wheel(e), { passive: false });
  return pointer;
}

/**
 * One press at a time, from down to up:
 *   pan    right/middle button or Space held: moves the view
 *   click  on empty image: places the active point on release (unless it moved: "none")
 *   grab   on a point: becomes "drag" once it moves, else a click (select or place) on release
 */
class CanvasPointer {
  /** @param {import("./editor.js").Editor} editor @param {any} hooks */
  constructor(editor, hooks) {
    this.editor = editor;
    this.hooks = hooks;
    this.canvas = editor.canvas;
    this.gesture = 0;
    /** @type {null|{mode: string, id: number, x: number, y: number, lastX: number,
     *          lastY: number, point?: number, grabDx?: number, grabDy?: number,
     *          group?: "skeleton"|"chain"|null, startX?: number, startY?: number,
     *          origin?: Array<{point: number, x: number, y: number, visible: boolean}>|null}}
     *   group drags move from `origin` by the cursor's image px since (startX, startY) */
    this.press = null;
  }

  /** Canvas CSS px of a mouse event. @param {MouseEvent} e */
  local(e) {
    const r = this.canvas.getBoundingClientRect();
    return { x: e.clientX - r.left, y: e.clientY - r.top };
  }

  /** The nearest shown point within reach of a canvas position, or -1. */
  pointUnder(s) {
    const { editor } = this;
    const shown = editor.pointsHere().map((v, p) => (editor.hidden.has(p) ? null : v));
    return editor.transform.hitTest(shown, s.x, s.y, HIT_RADIUS_PX, editor.active);
  }

  /** @param {PointerEvent} e */
  down(e) {
    const { editor } = this;
    this.hooks.onActivity();
    const s = this.local(e);
    this.canvas.setPointerCapture(e.pointerId);
    const base = { id: e.pointerId, x: s.x, y: s.y, lastX: s.x, lastY: s.y };
    if (e.button === 1 || e.button === 2 || (e.button === 0 && this.hooks.spaceHeld())) {
      this.press = { ...base, mode: "pan" };
      e.preventDefault();
      return;
    }
    if (e.button !== 0) return;
    const hit = editor.readOnly ? -1 : this.pointUnder(s);
    if (hit < 0) {
      this.press = { ...base, mode: "click" };
      return;
    }
    const v = editor.store.valueAt(hit, editor.frame);
    const at = editor.transform.toImage(s.x, s.y);
    this.gesture += 1;
    const group = e.shiftKey ? "skeleton" : (e.altKey || e.ctrlKey) ? "chain" : null;
    this.press = { ...base, mode: "grab", point: hit, grabDx: v.x - at.x, grabDy: v.y - at.y,
      group, startX: at.x, startY: at.y };
    if (group) e.preventDefault();
  }

  /** @param {PointerEvent} e */
  move(e) {
    const { editor, press } = this;
    const s = this.local(e);
    if (!press || press.id !== e.pointerId) {
      if (editor.readOnly) return;
      this.canvas.style.cursor = this.pointUnder(s) >= 0 ? "grab" : "crosshair";
      return;
    }
    const moved = Math.hypot(s.x - press.x, s.y - press.y) > CLICK_SLOP_PX;
    if (press.mode === "pan") {
      editor.panBy(s.x - press.lastX, s.y - press.lastY);
      this.hooks.onPan();
    } else if (press.mode === "grab" && moved) {
      press.mode = press.group ? "group" : "drag";
      editor.select(press.point);
      if (press.group) this.startGroup(press);
    } else if (press.mode === "click" && moved) {
      press.mode = "none";
    }
    if (press.mode === "drag") {
      const at = editor.transform.toImage(s.x, s.y);
      editor.movePoint(press.point, at.x + press.grabDx, at.y + press.grabDy,
        `drag-${this.gesture}`);
      this.canvas.style.cursor = "grabbing";
    } else if (press.mode === "group" && press.origin) {
      const at = editor.transform.toImage(s.x, s.y);
      editor.moveGroup(press.origin, at.x - press.startX, at.y - press.startY,
        `group-${this.gesture}`);
      this.canvas.style.cursor = "grabbing";
    }
    press.lastX = s.x;
    press.lastY = s.y;
  }

  /**
   * A group drag starts: which points move, from where. Nothing moves when the grabbed point
   * itself is locked (a lock holds against every drag).
   * @param {any} press
   */
  startGroup(press) {
    const { editor } = this;
    const refusal = editor.locked.has(press.point) ? editor.refusal(press.point) : null;
    if (refusal || editor.readOnly) {
      if (refusal) editor.onMessage(refusal, "error");
      press.origin = null;
      return;
    }
    press.origin = editor.groupOf(press.point, press.group);
  }

  /** @param {PointerEvent} e @param {boolean} cancelled */
  up(e, cancelled) {
    const { editor, press } = this;
    if (!press || press.id !== e.pointerId) return;
    if (!cancelled && press.mode === "grab") {
      const here = editor.store.valueAt(editor.active, editor.frame);
      if (here.x === null) press.mode = "click";
      else editor.select(press.point);
    }
    if (!cancelled && press.mode === "click") {
      const at = editor.transform.toImage(press.x, press.y);
      if (inImage(editor, at)) editor.placeActive(at.x, at.y);
    }
    this.press = null;
    this.hooks.onActivity();
  }

  /** Zooms about the cursor. @param {WheelEvent} e */
  wheel(e) {
    e.preventDefault();
    this.hooks.onActivity();
    const s = this.local(e);
    const pixels = e.deltaMode === 1 ? e.deltaY * 16 : e.deltaY;
    this.editor.zoomAt(s.x, s.y, Math.exp(-pixels * 0.002));
  }
}

/** Clicks outside the image place nothing (a stray click beside the frame is not a label). */
function inImage(editor, at) {
  const { width, height } = editor.task;
  return at.x >= -0.5 && at.y >= -0.5 && at.x < width - 0.5 && at.y < height - 0.5;
}
