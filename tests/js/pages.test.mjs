// The pages' module lists: every <link rel="modulepreload"> names a module the page imports (so
// a moved module cannot leave a stale or missing entry), and the worker-facing pages preload
// every module they import.
import assert from "node:assert/strict";
import { existsSync, readFileSync } from "node:fs";
import { dirname, join, relative } from "node:path";
import { test } from "node:test";
import { fileURLToPath } from "node:url";

const FRONTEND = fileURLToPath(new URL("../../frontend/", import.meta.url));
const IMPORT = /^\s*(?:import|export)\s[^;]*?from\s+"(\.{1,2}\/[^"]+)"/gm;

/** The modules a page's entry reaches through static imports, as paths from the page's folder. */
function staticImports(page, entry) {
  const folder = join(FRONTEND, page);
  const seen = new Set();
  const walk = (file) => {
    if (seen.has(file)) return;
    seen.add(file);
    for (const [, spec] of readFileSync(file, "utf8").matchAll(IMPORT)) {
      walk(join(dirname(file), spec));
    }
  };
  walk(join(folder, entry));
  return new Set([...seen].map((file) => relative(folder, file)));
}

/** The page's entry script and its preloaded modules. */
function pageModules(page) {
  const html = readFileSync(join(FRONTEND, page, "index.html"), "utf8");
  const entry = /<script type="module" src="([^"]+)"><\/script>/.exec(html)[1];
  const preloads = [...html.matchAll(/<link rel="modulepreload" href="([^"]+)">/g)].map((m) => m[1]);
  return { entry, preloads };
}

for (const page of ["annotate", "admin", "market"]) {
  test(`the ${page} page preloads only modules it imports`, () => {
    const { entry, preloads } = pageModules(page);
    const imported = staticImports(page, entry);
    assert.equal(new Set(preloads).size, preloads.length, "a module is listed twice");
    for (const href of preloads) {
      assert.ok(existsSync(join(FRONTEND, page, href)), `${page}: ${href} does not exist`);
      assert.ok(imported.has(href), `${page}: ${href} is preloaded but not imported`);
    }
  });
}

for (const page of ["annotate", "market"]) {
  test(`the ${page} page preloads every module it imports`, () => {
    const { entry, preloads } = pageModules(page);
    const missing = [...staticImports(page, entry)].filter(
      (file) => file !== entry && !preloads.includes(file));
    assert.deepEqual(missing, []);
  });
}
