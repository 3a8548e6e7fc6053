#!/usr/bin/env node
// Click objects on lodconvert's viewer page in headless Chromium and print what its inspect panel
// showed as one line of JSON; its command line, output and hang guard are those of drive.mjs
// (see there):
//
//   node tests/browser/inspect.mjs clicks BASE_URL PARAMS_JSON
//
// PARAMS: {page, clicks: [{point} or {at}]}: the page is clicked, in turn, where the world point
// `point` shows (the page's lodconvertViewer.screenPoint) or at `at`, fractions of the view's
// width and height, with the viewer where the page first puts it. The readout panel is hidden
// first: it covers part of the view, and a click on it is not one on the view. Result per click:
// the pixel clicked, the object selected, and the inspect panel (hidden, its heading and its rows
// as [header, cell or null]). Every wait is on page state.

import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..", "..");
const { chromium } = createRequire(path.join(root, "package.json"))("playwright-core");

const FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-gpu-watchdog"];
const NOISE = /GPU stall due to ReadPixels|GL Driver Message/;
const VIEWPORT = { width: 640, height: 480 };

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

/** The page pixel (CSS) of `click`: where its world point shows, or its fraction of the view. */
async function pixelOf(page, click) {
  if (click.point === undefined) {
    return evaluate(page, `finding ${click.at} of the view`, ([fx, fy]) => {
      const rect = document.getElementById("view").getBoundingClientRect();
      return { x: rect.left + fx * rect.width, y: rect.top + fy * rect.height };
    }, click.at);
  }
  const pixel = await evaluate(page, `projecting ${click.point}`,
    (point) => window.lodconvertViewer.screenPoint(point), click.point);
  if (pixel === null) throw new Error(`${click.point} is behind the viewer`);
  return pixel;
}

/** Click the view at `pixel`; resolves once the page handled the click. */
async function clickView(page, { x, y }) {
  const covered = await evaluate(page, "checking what is at the pixel", ([x, y]) => {
    const element = document.elementFromPoint(x, y);
    return document.getElementById("view").contains(element) ? null : String(element?.outerHTML);
  }, [x, y]);
  if (covered !== null) throw new Error(`(${x}, ${y}) is on ${covered.slice(0, 80)}, not the view`);
  const before = await evaluate(page, "counting clicks", () => window.lodconvertViewer.clicks);
  step = `clicking at (${x}, ${y})`;
  await page.mouse.click(x, y);
  const handled = (n) => window.lodconvertViewer.clicks > n;
  await waitFor(page, "the page handling the click", handled, before);
}

/** What the inspect panel shows. */
const panel = () => {
  const inspect = document.getElementById("inspect");
  return {
    selected: window.lodconvertViewer.selected,
    hidden: inspect.hidden,
    heading: inspect.querySelector("h2")?.textContent ?? null,
    rows: [...inspect.querySelectorAll("tr")].map((row) =>
      [row.querySelector("th").textContent, row.querySelector("td")?.textContent ?? null]),
  };
};

/** The one scenario: open params.page and make params.clicks. */
async function clicks(page) {
  step = `loading the viewer page ${params.page}`;
  await page.goto(`${base}/${params.page}`);
  await waitFor(page, "the viewer page loading", () => {
    return window.lodconvertViewer?.ready || window.lodconvertViewer?.error;
  });
  const error = await evaluate(page, "reading its error", () => window.lodconvertViewer.error);
  if (error) throw new Error(`viewer page: ${error}`);
  await evaluate(page, "hiding the readout panel", () => {
    document.getElementById("panel").style.visibility = "hidden";
  });
  const seen = [];
  for (const click of params.clicks) {
    const pixel = await pixelOf(page, click);
    await clickView(page, pixel);
    seen.push({ pixel, ...(await evaluate(page, "reading the inspect panel", panel)) });
  }
  return { clicks: seen };
}

async function main() {
  if (scenario !== "clicks") throw new Error(`unknown scenario ${scenario}`);
  const browser = await chromium.launch({
    executablePath: process.env.LODCONVERT_CHROMIUM || "/usr/bin/chromium",
    args: FLAGS,
    timeout: 0,
  });
  try {
    const page = await browser.newPage({ viewport: VIEWPORT });
    page.setDefaultTimeout(0);
    page.on("console", (m) => NOISE.test(m.text()) || log.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
    page.on("requestfailed", (r) => log.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
    page.on("response", (r) => r.status() >= 400 && log.push(`HTTP ${r.status()}: ${r.url()}`));
    return { ok: true, result: await clicks(page), console: log };
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
