#!/usr/bin/env node
// Move lodconvert's viewer page through distances and LOD scales in headless Chromium and print
// what it showed of its objects and LOD parents (cells) as one line of JSON; its command line,
// output and hang guard are those of drive.mjs (see there):
//
//   node tests/browser/hlod.mjs stops BASE_URL PARAMS_JSON
//
// PARAMS: {page (with its query, e.g. "d.x3d.html?lodscale=2"), stops: [{distance} or {key} or
// {lodScale}]}: per stop the page is moved by setDistance(distance), by pressing `key` on the
// distance slider, or given a new LOD scale (setLodScale, or typed into its field with
// `typed`), and read once settled: distance, lodScale, objects, cells, merged and the text of
// the readouts. Every wait is on page state.

import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..", "..");
const { chromium } = createRequire(path.join(root, "package.json"))("playwright-core");

const FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-gpu-watchdog"];
const NOISE = /GPU stall due to ReadPixels|GL Driver Message/;

const [scenario, base, json] = process.argv.slice(2);
const params = JSON.parse(json ?? "{}");
const safety = params.safety_ms ?? 600000;
const log = [];
let step = "starting Chromium";

const emit = (out) => process.stdout.write(JSON.stringify(out) + "\n");

setTimeout(() => {
  const error = `${step}: no result after ${safety / 1000} s (a guard far beyond a normal run)`;
  emit({ ok: false, error, console: log });
  process.exit(1);
}, safety).unref();

/** Wait, without a time limit, until `predicate(arg)` is true in the page. */
async function waitFor(page, what, predicate, arg = null) {
  step = what;
  await page.waitForFunction(predicate, arg, { timeout: 0, polling: 100 });
}

/** `page.evaluate`, recording what it is doing for the hang guard's message. */
function evaluate(page, what, fn, arg) {
  step = what;
  return page.evaluate(fn, arg);
}

/** Make one stop's move: resolves once the page has settled after it. */
async function move(page, stop) {
  if (stop.distance !== undefined) {
    const to = (d) => window.lodconvertViewer.setDistance(d);
    await evaluate(page, `moving to ${stop.distance}`, to, stop.distance);
    return;
  }
  if (stop.key !== undefined) {
    step = `pressing ${stop.key} on the slider`;
    await page.locator("#distance").press(stop.key);
  } else if (stop.typed) {
    step = `typing the LOD scale ${stop.lodScale}`;
    await page.locator("#lodscale").fill(String(stop.lodScale));
    await page.locator("#lodscale").press("Enter");
  } else {
    const scale = (s) => window.lodconvertViewer.setLodScale(s);
    await evaluate(page, `setting the LOD scale ${stop.lodScale}`, scale, stop.lodScale);
  }
  await waitFor(page, "the page settling", () => window.lodconvertViewer.settled);
}

/** What the page shows: its state and the text of its readouts. */
const shown = () => {
  const { distance, lodScale, objects, cells, merged } = window.lodconvertViewer;
  const text = (id) => document.getElementById(id).textContent;
  return { distance, lodScale, objects, cells, merged, readout: text("readout"), cellText: text("cells") };
};

/** The one scenario: open params.page and make params.stops. */
async function stops(page) {
  step = `loading the viewer page ${params.page}`;
  await page.goto(`${base}/${params.page}`);
  await waitFor(page, "the viewer page loading", () => {
    return window.lodconvertViewer?.ready || window.lodconvertViewer?.error;
  });
  const error = await evaluate(page, "reading its error", () => window.lodconvertViewer.error);
  if (error) throw new Error(`viewer page: ${error}`);
  const seen = [await evaluate(page, "reading the first view", shown)];
  for (const stop of params.stops) {
    await move(page, stop);
    seen.push(await evaluate(page, "reading the page", shown));
  }
  return { stops: seen };
}

async function main() {
  if (scenario !== "stops") throw new Error(`unknown scenario ${scenario}`);
  const browser = await chromium.launch({
    executablePath: process.env.LODCONVERT_CHROMIUM || "/usr/bin/chromium",
    args: FLAGS,
    timeout: 0,
  });
  try {
    const page = await browser.newPage({ viewport: { width: 640, height: 480 } });
    page.setDefaultTimeout(0);
    page.on("console", (m) => NOISE.test(m.text()) || log.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
    page.on("requestfailed", (r) => log.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
    page.on("response", (r) => r.status() >= 400 && log.push(`HTTP ${r.status()}: ${r.url()}`));
    return { ok: true, result: await stops(page), console: log };
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
