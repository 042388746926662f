/** Thin renderers of the portal's lists: they build DOM from API replies, nothing more. */

import { duration, money } from "./format.js";

/**
 * @param {string} tag
 * @param {Record<string, string>} [attrs]
 * @param {(Node|string)[]} [children]
 */
export function el(tag, attrs = {}, children = []) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) node.setAttribute(name, value);
  node.append(...children);
  return node;
}

/**
 * The HIT list: title, reward, time allotted, assignments available, and a preview link.
 * @param {HTMLTableSectionElement} body
 * @param {any[]} hits   GET /api/portal/hits
 */
export function renderHits(body, hits) {
  body.replaceChildren(...hits.map((hit) => el("tr", { "data-hit": hit.hit_id }, [
    el("td", {}, [el("a", { href: `#/hits/${encodeURIComponent(hit.hit_id)}`, class: "hit-title" },
      [hit.title]), el("div", { class: "muted" }, [hit.description])]),
    el("td", { class: "num" }, [money(hit.reward)]),
    el("td", { class: "num" }, [duration(hit.assignment_duration_s)]),
    el("td", { class: "num" }, [String(hit.available)]),
  ])));
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
    el("div", { class: "stat", id: "earned-paid" }, [el("b", {}, [money(paid)]), " paid"]),
    el("div", { class: "stat", id: "earned-pending" }, [el("b", {}, [money(pending)]),
      " awaiting review"]),
    el("div", { class: "stat" }, [el("b", {}, [money(bonuses)]), " in bonuses"]),
  );
  body.replaceChildren(...data.assignments.map((a) => el("tr", {
    "data-assignment": a.assignment_id, "data-status": a.status,
  }, [
    el("td", {}, [a.work_url
      ? el("a", { href: `#/work/${encodeURIComponent(a.assignment_id)}` }, [a.title])
      : a.title]),
    el("td", {}, [el("span", { class: `status status-${a.status.toLowerCase()}` }, [a.status])]),
    el("td", { class: "num" }, [money(a.reward)]),
    el("td", { class: "num" }, [Number(a.bonus) > 0 ? money(a.bonus) : "–"]),
    el("td", { class: "feedback" }, [a.feedback || ""]),
  ])));
}

/**
 * An iframe that frames the annotation page as MTurk does.
 * @param {string} src
 * @param {number} height  FrameHeight of the HIT (px)
 */
export function taskFrame(src, height) {
  const frame = el("iframe", {
    src, title: "HIT", class: "task-frame",
    sandbox: "allow-scripts allow-forms allow-same-origin allow-top-navigation-by-user-activation",
  });
  frame.style.height = `${Math.max(height, 400)}px`;
  return frame;
}
