#!/usr/bin/env node
// Drive X_ITE through an X3D file's prism switching in headless Chromium and print, as one line
// of JSON, which level each object showed at each stop.
//
//   node tests/browser/prism.mjs BASE_URL PARAMS_JSON
//
// BASE_URL serves the test site (pages/, node_modules/ and the files under test, see
// conftest.py). PARAMS: file (the .x3d, in the site), objects ([{base, switches}]: an object's
// DEF base and its number of prism Switches), stops ([{position, expected}]: where to put the
// viewer, world coordinates, or no position for the viewer X_ITE starts with; and the level
// each object should show there), safety_ms. At a stop, frames are drawn until every object
// shows its expected level, or SETTLE_FRAMES frames (a count, not a time: a slow machine waits
// longer); the levels shown then are reported, read from the Switches' whichChoice: an object
// shows level k for the first Switch k at its near choice (0), its last level (or nothing,
// culled) when none is. Output: {"ok": true, "result": {"stops": [[{level, choices}, ...],
// ...]}, "console": [...]} or {"ok": false, "error": "...", "console": [...]}; exit status 0
// or 1. The one clock is safety_ms, a guard against a hung browser far beyond a normal run.

import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..", "..");
const { chromium } = createRequire(path.join(root, "package.json"))("playwright-core");

const FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-gpu-watchdog"];
const SETTLE_FRAMES = 120;

const [base, json] = process.argv.slice(2);
const params = JSON.parse(json ?? "{}");
const log = [];
let step = "starting Chromium";

const emit = (out) => process.stdout.write(JSON.stringify(out) + "\n");

setTimeout(() => {
  const error = `${step}: no result after ${params.safety_ms / 1000} s (a guard far beyond a normal run)`;
  emit({ ok: false, error, console: log });
  process.exit(1); // Playwright kills the browser on exit
}, params.safety_ms ?? 600000).unref();

/** In the page: draw frames until the objects show `expected`, then report what they show. */
async function settle({ objects, expected, frames }) {
  const scene = document.querySelector("x3d-canvas").browser.currentScene;
  const read = () => objects.map(({ base, switches }) => {
    const choices = [];
    for (let k = 0; k < switches; k++) {
      choices.push(scene.getNamedNode(`${base}_Switch${k}`).whichChoice);
    }
    const near = choices.indexOf(0);
    return { level: near < 0 ? switches : near, choices };
  });
  const frame = () => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)));
  let seen = read();
  for (let i = 0; i < frames && seen.some((s, j) => s.level !== expected[j]); i++) {
    await frame();
    seen = read();
  }
  return seen;
}

async function run(page) {
  step = "loading the X_ITE test page";
  await page.goto(`${base}/pages/x_ite.html`);
  step = "the X_ITE test page starting";
  await page.waitForFunction(() => window.harness, null, { timeout: 0, polling: 100 });
  step = `X_ITE loading ${params.file}`;
  await page.evaluate((url) => window.harness.load(url, []), `${base}/${params.file}`);
  const stops = [];
  for (const stop of params.stops) {
    if (stop.position) {
      step = `placing the viewer at ${stop.position}`;
      await page.evaluate((p) => window.harness.place(p), stop.position);
    }
    step = `X_ITE settling at ${stop.position ?? "its start"}`;
    const arg = { objects: params.objects, expected: stop.expected, frames: SETTLE_FRAMES };
    stops.push(await page.evaluate(settle, arg));
  }
  return { stops };
}

async function main() {
  const browser = await chromium.launch({
    executablePath: process.env.LODCONVERT_CHROMIUM || "/usr/bin/chromium",
    args: FLAGS,
    timeout: 0,
  });
  try {
    const page = await browser.newPage({ viewport: { width: 640, height: 480 } });
    page.setDefaultTimeout(0); // no time limits: the guard above catches a hung browser
    page.on("console", (m) => log.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
    page.on("response", (r) => r.status() >= 400 && log.push(`HTTP ${r.status()}: ${r.url()}`));
    return { ok: true, result: await run(page), console: log };
  } finally {
    step = "closing Chromium";
    await browser.close();
  }
}

main().then(
  (out) => emit(out),
  (error) => {
    emit({ ok: false, error: String(error?.message ?? error), console: log });
    process.exitCode = 1;
  },
);
