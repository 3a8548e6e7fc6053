#!/usr/bin/env node
// Drive a web3D viewer in headless Chromium and print what it saw as one line of JSON.
//
//   node tests/browser/drive.mjs SCENARIO BASE_URL PARAMS_JSON
//
// BASE_URL serves the test site (pages/, node_modules/ and the files under test, see
// conftest.py). Output: {"ok": true, "result": {...}, "console": [...], "renderer": "..."} or
// {"ok": false, "error": "...", "console": [...]}; exit status 0 or 1. Every wait is on page
// state (waitForFunction on a flag, a promise the page resolves after its frames are drawn),
// never a fixed sleep nor a time limit: a loaded machine is slower, not wrong. The one clock is
// PARAMS.safety_ms, a guard against a hung browser far beyond any normal run, which ends the run
// with an error naming the step it hung in. "console" holds the page's console messages, page
// errors and failed requests, for the test's failure message.
//
// playwright-core is resolved from node_modules at the repository root; Chromium is Debian's
// /usr/bin/chromium (LODCONVERT_CHROMIUM overrides), rendering WebGL with SwiftShader.

import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..", "..");
const { chromium } = createRequire(path.join(root, "package.json"))("playwright-core");

const FLAGS = [
  "--headless",
  "--no-sandbox",
  "--disable-gpu",
  "--disable-gpu-watchdog", // SwiftShader frames of a large model on a loaded machine are slow
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--no-first-run",
];
const NOISE = /GPU stall due to ReadPixels|GL Driver Message/;
const VIEWPORT = { width: 640, height: 480 };

const [scenario, base, json] = process.argv.slice(2);
const params = JSON.parse(json ?? "{}");
const safety = params.safety_ms ?? 600000;
const log = [];
let step = "starting Chromium";

/** Print the run's one line of JSON. */
const emit = (out) => process.stdout.write(JSON.stringify(out) + "\n");

setTimeout(() => {
  const error = `${step}: no result after ${safety / 1000} s (a guard far beyond a normal run)`;
  emit({ ok: false, error, console: log });
  process.exit(1); // Playwright kills the browser on exit
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

/**
 * Pixels of the element `selector` that differ from the background (by more than 24 in a
 * channel; the background is the top-left pixel unless given): their number, `foreground`, and
 * their mean brightness (Rec. 709 luma, 0-255; null without any), `brightness`. The screenshot
 * is decoded in the page itself.
 */
async function pixels(page, selector, background = null) {
  step = `screenshot of ${selector}`;
  const png = await page.locator(selector).screenshot();
  return evaluate(page, `reading the screenshot of ${selector}`,
    async ({ data, background }) => {
      const bytes = Uint8Array.from(atob(data), (c) => c.charCodeAt(0));
      const bitmap = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
      const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
      const context = canvas.getContext("2d");
      context.drawImage(bitmap, 0, 0);
      const rgba = context.getImageData(0, 0, bitmap.width, bitmap.height).data;
      const bg = background ?? [rgba[0], rgba[1], rgba[2]];
      let count = 0;
      let luma = 0;
      for (let i = 0; i < rgba.length; i += 4) {
        if ([0, 1, 2].some((k) => Math.abs(rgba[i + k] - bg[k]) > 24)) {
          count += 1;
          luma += 0.2126 * rgba[i] + 0.7152 * rgba[i + 1] + 0.0722 * rgba[i + 2];
        }
      }
      return { foreground: count, brightness: count ? luma / count : null };
    },
    { data: png.toString("base64"), background },
  );
}

const fileUrl = (file) => `${base}/${file}`;

const scenarios = {
  /** X_ITE: load params.file, then per stop place the viewer and read params.lod's level. */
  async x_ite(page) {
    step = "loading the X_ITE test page";
    await page.goto(`${base}/pages/x_ite.html`);
    await waitFor(page, "the X_ITE test page starting", () => window.harness);
    const firstFrameMs = await evaluate(page, `X_ITE loading ${params.file}`,
      ([url, lods]) => window.harness.load(url, lods),
      [fileUrl(params.file), params.lod ? [params.lod] : []],
    );
    const stops = [];
    for (const stop of params.stops ?? []) {
      const [x, y, z] = params.center;
      const place = (p) => window.harness.place(p);
      const at = [x, y, z + stop.distance];
      await evaluate(page, `placing the viewer at ${stop.distance}`, place, at);
      const level = await evaluate(page, `X_ITE settling at ${stop.distance}`,
        ([lod, level]) => window.harness.settle(lod, level), [params.lod, stop.level]);
      stops.push({ distance: stop.distance, level, ...(await pixels(page, "x3d-canvas")) });
    }
    return { firstFrameMs, stops };
  },

  /** X3DOM: load params.file in an Inline, wait until it is drawn, collect X3DOM's log. */
  async x3dom(page) {
    step = "loading the X3DOM test page";
    await page.goto(`${base}/pages/x3dom.html?file=${encodeURIComponent(fileUrl(params.file))}`);
    await waitFor(page, "X3DOM loading the Inline", () => {
      return window.harness?.loaded || window.harness?.error;
    });
    const error = await evaluate(page, "reading X3DOM's error", () => window.harness.error);
    if (error) throw new Error(`X3DOM: ${error}`);
    await waitFor(page, "X3DOM drawing", () => {
      const doc = window.x3dom?.canvases?.[0]?.doc;
      return doc && doc.downloadCount === 0 && !doc.needRender;
    });
    const entries = await evaluate(page, "reading X3DOM's log", () =>
      [...(window.x3dom.debug.logContainer?.childNodes ?? [])].map((n) => n.textContent),
    );
    return {
      loadMs: await evaluate(page, "reading X3DOM's load time", () => window.harness.elapsed),
      problems: entries.filter((t) => !t.startsWith("INFO")),
      ...(await pixels(page, "x3d canvas", [255, 255, 255])),
    };
  },

  /** Babylon.js: load params.file (MSFT_lod limited to params.maxLods levels if given). */
  async babylon(page) {
    step = "loading the Babylon.js test page";
    await page.goto(`${base}/pages/babylon.html`);
    await waitFor(page, "the Babylon.js test page starting", () => window.harness);
    const result = await evaluate(page, `Babylon.js loading ${params.file}`,
      ([url, maxLods]) => window.harness.load(url, maxLods),
      [fileUrl(params.file), params.maxLods ?? null],
    );
    return { ...result, ...(await pixels(page, "canvas")) };
  },

  /** three.js: load params.file and draw node params.node alone. */
  async three(page) {
    step = "loading the three.js test page";
    await page.goto(`${base}/pages/three.html`);
    await waitFor(page, "the three.js test page starting", () => window.harness);
    const result = await evaluate(page, `three.js loading ${params.file}`,
      ([url, node]) => window.harness.show(url, node),
      [fileUrl(params.file), params.node],
    );
    return { ...result, ...(await pixels(page, "canvas")) };
  },

  /**
   * lodconvert's viewer page params.page: per stop move the viewer, by setDistance(distance) or
   * by pressing `key` on the distance slider, and read every object's state once drawn there
   * (with `shot`, the page is saved there as a PNG first).
   */
  async viewer(page) {
    step = `loading the viewer page ${params.page}`;
    await page.goto(fileUrl(params.page));
    await waitFor(page, "the viewer page loading", () => {
      return window.lodconvertViewer?.ready || window.lodconvertViewer?.error;
    });
    const error = await evaluate(page, "reading its error", () => window.lodconvertViewer.error);
    if (error) throw new Error(`viewer page: ${error}`);
    const stops = [];
    for (const stop of params.stops) {
      if (stop.key === undefined) {
        const move = (d) => window.lodconvertViewer.setDistance(d);
        await evaluate(page, `moving to ${stop.distance}`, move, stop.distance);
      } else {
        step = `pressing ${stop.key} on the slider`;
        await page.locator("#distance").press(stop.key);
        const settled = () => window.lodconvertViewer.settled;
        await waitFor(page, `moving after ${stop.key} on the slider`, settled);
      }
      if (stop.shot) {
        step = `saving a screenshot at ${stop.distance}`;
        await page.screenshot({ path: stop.shot });
      }
      const panel = (shown) => { document.getElementById("panel").style.visibility = shown; };
      await evaluate(page, "hiding the panel", panel, "hidden");
      const seen = await pixels(page, "#view");
      await evaluate(page, "showing the panel", panel, "");
      stops.push({
        ...(await evaluate(page, "reading the viewer's state", () => {
          const { distance, objects } = window.lodconvertViewer;
          return { distance, objects, readout: document.getElementById("readout").textContent };
        })),
        ...seen,
      });
    }
    const loadMs = await evaluate(page, "reading its load time", () => lodconvertViewer.loadMs);
    return { loadMs, stops };
  },
};

async function main() {
  if (!(scenario in scenarios)) throw new Error(`unknown scenario ${scenario}`);
  const browser = await chromium.launch({
    executablePath: process.env.LODCONVERT_CHROMIUM || "/usr/bin/chromium",
    args: FLAGS,
    timeout: 0,
  });
  try {
    const page = await browser.newPage({ viewport: VIEWPORT });
    page.setDefaultTimeout(0); // no time limits: the guard above catches a hung browser
    page.on("console", (m) => NOISE.test(m.text()) || log.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
    page.on("requestfailed", (r) => log.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
    page.on("response", (r) => r.status() >= 400 && log.push(`HTTP ${r.status()}: ${r.url()}`));
    const result = await scenarios[scenario](page);
    const renderer = await evaluate(page, "reading the WebGL renderer", () => {
      const gl = document.createElement("canvas").getContext("webgl2");
      const info = gl?.getExtension("WEBGL_debug_renderer_info");
      return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : "no WebGL 2";
    });
    return { ok: true, result, console: log, renderer };
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
