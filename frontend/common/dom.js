/** DOM helpers of every page: an element by its id, and elements built from tag, attributes
 * and children. */

const SVG = "http://www.w3.org/2000/svg";

/**
 * The page's element with this id.
 * @param {string} id
 * @returns {HTMLElement}
 */
export const $ = (id) => /** @type {HTMLElement} */ (document.getElementById(id));

/**
 * An attribute; ``style`` through the CSSOM, which the pages' Content-Security-Policy allows
 * (a style attribute set as markup is an inline style it refuses).
 * @param {HTMLElement|SVGElement} node
 * @param {string} name
 * @param {string} value
 */
function setAttr(node, name, value) {
  if (name === "style") node.style.cssText = value;
  else node.setAttribute(name, value);
}

/**
 * @param {string} tag
 * @param {Record<string, string>} [attrs]
 * @param {(Node|string)[]} [children]
 */
export function el(tag, attrs = {}, children = []) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) setAttr(node, name, value);
  node.append(...children);
  return node;
}

/**
 * @param {string} tag
 * @param {Record<string, string|number>} [attrs]
 * @param {(Node|string)[]} [children]
 */
export function svg(tag, attrs = {}, children = []) {
  const node = document.createElementNS(SVG, tag);
  for (const [name, value] of Object.entries(attrs)) setAttr(node, name, String(value));
  node.append(...children);
  return node;
}
