// What the Node drivers of the browser tests (drive.mjs, inspect.mjs, hlod.mjs, page.mjs,
// prism.mjs) share: each drives headless Chromium through one of its scenarios and prints what
// it saw as one line of JSON.
//
//   node tests/browser/DRIVER.mjs SCENARIO BASE_URL PARAMS_JSON
//
// BASE_URL serves the test site (pages/, node_modules/ and the files under test, see
// conftest.py). Output: {"ok": true, "result": {...}, "console": [...]} (drive.mjs adds
// "renderer": "...") or {"ok": false, "error": "...", "console": [...]}; exit status 0 or 1.
// Every wait is on page state (waitForFunction on a flag, a promise the page resolves after its
// frames are drawn), never a fixed sleep nor a time limit: a loaded machine is slower, not wrong.
// The one clock is PARAMS.safety_ms, a guard against a hung browser far beyond any normal run,
// which ends the run with an error naming the step it hung in. "console" holds the page's
// console messages (less Chromium's GPU noise), page errors, failed requests and HTTP errors,
// for the test's failure message.
//
// playwright-core is resolved from node_modules at the repository root; Chromium is Debian's
// /usr/bin/chromium (LODCONVERT_CHROMIUM overrides), rendering WebGL with SwiftShader.
//
// A driver is a table of scenarios, `async (page, {base, params}) => result`, handed to `run`;
// its scenarios record what they are doing (`doing`, `waitFor`, `evaluate`) for the guard.

import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..", "..");
const { chromium } = createRequire(path.join(root, "package.json"))("playwright-core");

export const FLAGS = [
  "--headless",
  "--no-sandbox",
  "--disable-gpu",
  "--disable-gpu-watchdog", // SwiftShader frames of a large model on a loaded machine are slow
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--no-first-run",
];
export const NOISE = /GPU stall due to ReadPixels|GL Driver Message/;
export const VIEWPORT = { width: 640, height: 480 };

const log = [];
let step = "starting Chromium";

/** Print the run's one line of JSON. */
export const emit = (out) => process.stdout.write(JSON.stringify(out) + "\n");

/** Record what the run is doing now, for the hang guard's message. */
export function doing(what) {
  step = what;
}

/** Wait, without a time limit, until `predicate(arg)` is true in the page. */
export async function waitFor(page, what, predicate, arg = null) {
  step = what;
  await page.waitForFunction(predicate, arg, { timeout: 0, polling: 100 });
}

/** `page.evaluate`, recording what it is doing for the hang guard's message. */
export function evaluate(page, what, fn, arg) {
  step = what;
  return page.evaluate(fn, arg);
}

/** Open the test page pages/`name`.html of the viewer library `library` and wait until it has
 * set up its window.harness. */
export async function openTestPage(page, base, name, library) {
  step = `loading the ${library} test page`;
  await page.goto(`${base}/pages/${name}.html`);
  await waitFor(page, `the ${library} test page starting`, () => window.harness);
}

/** Open lodconvert's viewer page `file` (with its query, if any) and wait until it is ready;
 * fails with the page's error if it has one. */
export async function openViewer(page, base, file) {
  step = `loading the viewer page ${file}`;
  await page.goto(`${base}/${file}`);
  await waitFor(page, "the viewer page loading", () => {
    return window.lodconvertViewer?.ready || window.lodconvertViewer?.error;
  });
  const error = await evaluate(page, "reading its error", () => window.lodconvertViewer.error);
  if (error) throw new Error(`viewer page: ${error}`);
}

/** In the page: the WebGL 2 renderer's name. */
const webglRenderer = () => {
  const gl = document.createElement("canvas").getContext("webgl2");
  const info = gl?.getExtension("WEBGL_debug_renderer_info");
  return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : "no WebGL 2";
};

/** Open Chromium, run the scenario on a new page, close it: the output line's object. */
async function session(scenarios, scenario, context, renderer) {
  if (!Object.hasOwn(scenarios, scenario)) throw new Error(`unknown scenario ${scenario}`);
  const browser = await chromium.launch({
    executablePath: process.env.LODCONVERT_CHROMIUM || "/usr/bin/chromium",
    args: FLAGS,
    timeout: 0,
  });
  try {
    const page = await browser.newPage({ viewport: VIEWPORT });
    page.setDefaultTimeout(0); // no time limits: the guard catches a hung browser
    page.on("console", (m) => NOISE.test(m.text()) || log.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
    page.on("requestfailed", (r) => log.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
    page.on("response", (r) => r.status() >= 400 && log.push(`HTTP ${r.status()}: ${r.url()}`));
    const out = { ok: true, result: await scenarios[scenario](page, context), console: log };
    if (renderer) out.renderer = await evaluate(page, "reading the WebGL renderer", webglRenderer);
    return out;
  } finally {
    step = "closing Chromium";
    await browser.close();
  }
}

/**
 * Run the driver with the scenarios table `scenarios` ({name: async (page, {base, params}) =>
 * result}): read SCENARIO BASE_URL PARAMS_JSON from `argv`, arm the hang guard, run the
 * scenario and print the output line; exit status 0 or 1. With `renderer`, the output also
 * holds the WebGL renderer's name.
 */
export function run(scenarios, { argv = process.argv.slice(2), renderer = false } = {}) {
  const [scenario, base, json] = argv;
  const params = JSON.parse(json ?? "{}");
  const safety = params.safety_ms ?? 600000;
  setTimeout(() => {
    const error = `${step}: no result after ${safety / 1000} s (a guard far beyond a normal run)`;
    emit({ ok: false, error, console: log });
    process.exit(1); // Playwright kills the browser on exit
  }, safety).unref();
  session(scenarios, scenario, { base, params }, renderer).then(
    (out) => emit(out),
    (error) => {
      emit({ ok: false, error: String(error?.message ?? error), console: log });
      process.exitCode = 1;
    },
  );
}
