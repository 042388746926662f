/** Thin renderers of the portal's lists: they build DOM from API replies, nothing more. */

import { el } from "../common/dom.js";
import { dollars, duration } from "../common/format.js";

/**
 * What a HIT's row says about its task: "right hand · camera 3 of 8 · 72 frames" (the camera's
 * serial only in the row's tooltip: it means nothing to a worker).
 * @param {{target: string, view: string, view_name: string, frames: number} | null} task
 */
export function taskFacts(task) {
  return task ? `${task.target} · ${task.view_name} · ${task.frames} frames` : "";
}

/**
 * The marks on a HIT's row, as data: "assigned to you" on a team task assigned to this worker
 * alone, then the worker's own assignment (a link back to an accepted one, or "submitted").
 * @param {{assigned_to_me?: boolean, mine: {assignment_id: string, status: string} | null}} hit
 * @returns {{text: string, kind: string, href?: string}[]}
 */
export function hitMarks(hit) {
  const marks = [];
  if (hit.assigned_to_me) marks.push({ text: "assigned to you", kind: "assigned" });
  const mine = hit.mine;
  if (mine?.status === "Accepted") {
    marks.push({ text: "accepted · continue", kind: "accepted",
      href: `#/work/${encodeURIComponent(mine.assignment_id)}` });
  } else if (mine) {
    marks.push({ text: mine.status.toLowerCase(), kind: mine.status.toLowerCase() });
  }
  return marks;
}

/**
 * One mark as an element: a link where it has one.
 * @param {{text: string, kind: string, href?: string}} mark
 * @returns {HTMLElement}
 */
function markElement(mark) {
  const attrs = { class: `mark mark-${mark.kind}`, ...(mark.href ? { href: mark.href } : {}) };
  return el(mark.href ? "a" : "span", attrs, [mark.text]);
}

/**
 * The HIT list: a thumbnail of the view, the title, the task (target, view, frames), the
 * worker's mark, reward, time allotted, assignments available.
 * @param {HTMLTableSectionElement} body
 * @param {any[]} hits   GET /api/portal/hits?mine=true
 */
export function renderHits(body, hits) {
  body.replaceChildren(...hits.map((hit) => {
    const link = hit.mine?.status === "Accepted"
      ? `#/work/${encodeURIComponent(hit.mine.assignment_id)}`
      : `#/hits/${encodeURIComponent(hit.hit_id)}`;
    const thumb = hit.thumbnail_url
      ? el("img", { class: "thumb", src: hit.thumbnail_url, width: "96",
        alt: `first frame of ${hit.task.view_name}` })
      : el("div", { class: "thumb thumb-none" });
    const marks = hitMarks(hit).flatMap((mark) => [" ", markElement(mark)]);
    const row = el("tr", { "data-hit": hit.hit_id }, [
      el("td", { class: "thumb-cell" }, [thumb]),
      el("td", {}, [
        el("a", { href: link, class: "hit-title" }, [hit.title]),
        el("div", { class: "facts", ...(hit.task ? { title: `camera serial ${hit.task.view}` } : {}) },
          [taskFacts(hit.task), ...marks]),
        el("div", { class: "muted" }, [hit.description]),
      ]),
      el("td", { class: "num" }, [dollars(hit.reward)]),
      el("td", { class: "num" }, [duration(hit.assignment_duration_s, "minute")]),
      el("td", { class: "num" }, [String(hit.available)]),
    ]);
    if (hit.mine) row.dataset.mine = hit.mine.status;
    return row;
  }));
}

/**
 * Earnings summary and one row per assignment with status, reward, bonus and feedback.
 * @param {HTMLElement} summary
 * @param {HTMLTableSectionElement} body
 * @param {any} data   GET /api/portal/assignments
 */
export function renderEarnings(summary, body, data) {
  const { paid, pending, bonuses } = data.earnings;
  summary.replaceChildren(
    el("div", { class: "stat", id: "earned-paid" }, [el("b", {}, [dollars(paid)]), " paid"]),
    el("div", { class: "stat", id: "earned-pending" }, [el("b", {}, [dollars(pending)]),
      " awaiting review"]),
    el("div", { class: "stat" }, [el("b", {}, [dollars(bonuses)]), " in bonuses"]),
  );
  body.replaceChildren(...data.assignments.map((a) => el("tr", {
    "data-assignment": a.assignment_id, "data-status": a.status,
  }, [
    el("td", {}, [a.work_url
      ? el("a", { href: `#/work/${encodeURIComponent(a.assignment_id)}` }, [a.title])
      : a.title]),
    el("td", {}, [el("span", { class: `status status-${a.status.toLowerCase()}` }, [a.status])]),
    el("td", { class: "num" }, [dollars(a.reward)]),
    el("td", { class: "num" }, [Number(a.bonus) > 0 ? dollars(a.bonus) : "–"]),
    el("td", { class: "feedback" }, [a.feedback || ""]),
  ])));
}

/** Room kept under the framed page (px): its border and a little air. */
const FRAME_MARGIN_PX = 6;
const MIN_FRAME_PX = 320;

/**
 * The frame's height that fills the window below its top edge.
 * @param {number} viewportHeight  window.innerHeight (px)
 * @param {number} top             the frame's top edge in the viewport (px)
 */
export function fittedHeight(viewportHeight, top) {
  return Math.max(MIN_FRAME_PX, Math.floor(viewportHeight - top - FRAME_MARGIN_PX));
}

/**
 * An iframe that frames the annotation page as MTurk does, as tall as the window leaves room
 * for (the page lays itself out to its frame, so its timeline stays in view); it follows the
 * window as it is resized.
 * @param {string} src
 */
export function taskFrame(src) {
  const frame = /** @type {HTMLIFrameElement} */ (el("iframe", {
    src, title: "HIT", class: "task-frame",
    sandbox: "allow-scripts allow-forms allow-same-origin allow-top-navigation-by-user-activation",
  }));
  const fit = () => {
    if (!frame.isConnected) {
      window.removeEventListener("resize", fit);
      return;
    }
    const top = frame.getBoundingClientRect().top + window.scrollY;
    frame.style.height = `${fittedHeight(window.innerHeight, top)}px`;
  };
  frame.style.height = `${MIN_FRAME_PX}px`;
  window.addEventListener("resize", fit);
  requestAnimationFrame(fit);
  frame.addEventListener("load", fit);
  // The framed page takes the keys at once (arrows, shortcuts), without a click in it first;
  // it puts them on its image itself once its frames are in.
  frame.addEventListener("load", () => frame.focus());
  return frame;
}
