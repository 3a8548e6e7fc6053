#!/usr/bin/env node
// Drive a web3D viewer in headless Chromium and print what it saw as one line of JSON.
//
//   node tests/browser/drive.mjs SCENARIO BASE_URL PARAMS_JSON
//
// BASE_URL serves the test site (pages/, node_modules/ and the files under test, see
// conftest.py). Output: {"ok": true, "result": {...}, "console": [...], "renderer": "..."} or
// {"ok": false, "error": "...", "console": [...]}; exit status 0 or 1. Every wait is on page
// state (waitForFunction), never a fixed sleep; "console" holds the page's console messages,
// page errors and failed requests, for the test's failure message.
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
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--no-first-run",
];
const NOISE = /GPU stall due to ReadPixels|GL Driver Message/;
const VIEWPORT = { width: 640, height: 480 };

const [scenario, base, json] = process.argv.slice(2);
const params = JSON.parse(json ?? "{}");
const timeout = params.timeout_ms ?? 30000;
const log = [];

/** Wait until `predicate(arg)` is true in the page; fail with `what` otherwise. */
async function waitFor(page, what, predicate, arg = null) {
  try {
    await page.waitForFunction(predicate, arg, { timeout, polling: 100 });
  } catch (error) {
    throw new Error(`${what} (waited ${timeout / 1000} s: ${error.message.split("\n")[0]})`);
  }
}

/** Like waitFor, but a miss is no error: whether the page reached the state in time. */
async function reached(page, predicate, arg) {
  try {
    await page.waitForFunction(predicate, arg, { timeout: Math.min(timeout, 10000), polling: 100 });
    return true;
  } catch {
    return false;
  }
}

/**
 * Pixels of the element `selector` that differ from the background (by more than 24 in a
 * channel); the background is the top-left pixel unless given. The screenshot is decoded in
 * the page itself.
 */
async function foreground(page, selector, background = null) {
  const png = await page.locator(selector).screenshot();
  return page.evaluate(
    async ({ data, background }) => {
      const bytes = Uint8Array.from(atob(data), (c) => c.charCodeAt(0));
      const bitmap = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
      const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
      const context = canvas.getContext("2d");
      context.drawImage(bitmap, 0, 0);
      const pixels = context.getImageData(0, 0, bitmap.width, bitmap.height).data;
      const bg = background ?? [pixels[0], pixels[1], pixels[2]];
      let count = 0;
      for (let i = 0; i < pixels.length; i += 4) {
        if ([0, 1, 2].some((k) => Math.abs(pixels[i + k] - bg[k]) > 24)) count += 1;
      }
      return count;
    },
    { data: png.toString("base64"), background },
  );
}

const fileUrl = (file) => `${base}/${file}`;

const scenarios = {
  /** X_ITE: load params.file, then per stop place the viewer and read params.lod's level. */
  async x_ite(page) {
    await page.goto(`${base}/pages/x_ite.html`);
    await waitFor(page, "the X_ITE test page did not start", () => window.harness);
    const firstFrameMs = await page.evaluate(
      ([url, lods]) => window.harness.load(url, lods),
      [fileUrl(params.file), params.lod ? [params.lod] : []],
    );
    const stops = [];
    for (const stop of params.stops ?? []) {
      const [x, y, z] = params.center;
      await page.evaluate((p) => window.harness.place(p), [x, y, z + stop.distance]);
      await reached(page, ([lod, level]) => window.harness.level(lod) === level, [params.lod, stop.level]);
      await page.evaluate(() => window.harness.frame());
      stops.push({
        distance: stop.distance,
        level: await page.evaluate((lod) => window.harness.level(lod), params.lod),
        foreground: await foreground(page, "x3d-canvas"),
      });
    }
    return { firstFrameMs, stops };
  },

  /** X3DOM: load params.file in an Inline, wait until it is drawn, collect X3DOM's log. */
  async x3dom(page) {
    await page.goto(`${base}/pages/x3dom.html?file=${encodeURIComponent(fileUrl(params.file))}`);
    await waitFor(page, "X3DOM did not load the Inline", () => window.harness?.loaded || window.harness?.error);
    const error = await page.evaluate(() => window.harness.error);
    if (error) throw new Error(`X3DOM: ${error}`);
    await waitFor(page, "X3DOM did not finish drawing", () => {
      const doc = window.x3dom?.canvases?.[0]?.doc;
      return doc && doc.downloadCount === 0 && !doc.needRender;
    });
    const entries = await page.evaluate(() =>
      [...(window.x3dom.debug.logContainer?.childNodes ?? [])].map((n) => n.textContent),
    );
    return {
      loadMs: await page.evaluate(() => window.harness.elapsed),
      problems: entries.filter((t) => !t.startsWith("INFO")),
      foreground: await foreground(page, "x3d canvas", [255, 255, 255]),
    };
  },

  /** Babylon.js: load params.file (MSFT_lod limited to params.maxLods levels if given). */
  async babylon(page) {
    await page.goto(`${base}/pages/babylon.html`);
    await waitFor(page, "the Babylon.js test page did not start", () => window.harness);
    const result = await page.evaluate(
      ([url, maxLods]) => window.harness.load(url, maxLods),
      [fileUrl(params.file), params.maxLods ?? null],
    );
    return { ...result, foreground: await foreground(page, "canvas") };
  },

  /** three.js: load params.file and draw node params.node alone. */
  async three(page) {
    await page.goto(`${base}/pages/three.html`);
    await waitFor(page, "the three.js test page did not start", () => window.harness);
    const result = await page.evaluate(
      ([url, node]) => window.harness.show(url, node),
      [fileUrl(params.file), params.node],
    );
    return { ...result, foreground: await foreground(page, "canvas") };
  },

  /** lodconvert's viewer page params.page: per stop set the distance, read the first object. */
  async viewer(page) {
    await page.goto(fileUrl(params.page));
    await waitFor(page, "the viewer page did not load", () => window.lodconvertViewer?.ready || window.lodconvertViewer?.error);
    const error = await page.evaluate(() => window.lodconvertViewer.error);
    if (error) throw new Error(`viewer page: ${error}`);
    const stops = [];
    for (const stop of params.stops) {
      await page.evaluate((d) => window.lodconvertViewer.setDistance(d), stop.distance);
      await reached(page, (level) => window.lodconvertViewer.objects[0].level === level, stop.level);
      await page.evaluate(() => { document.getElementById("panel").style.visibility = "hidden"; });
      const pixels = await foreground(page, "#view");
      await page.evaluate(() => { document.getElementById("panel").style.visibility = ""; });
      stops.push({
        ...(await page.evaluate(() => window.lodconvertViewer.objects[0])),
        readout: await page.evaluate(() => document.getElementById("readout").textContent),
        foreground: pixels,
      });
    }
    return { loadMs: await page.evaluate(() => window.lodconvertViewer.loadMs), stops };
  },
};

async function main() {
  if (!(scenario in scenarios)) throw new Error(`unknown scenario ${scenario}`);
  const browser = await chromium.launch({
    executablePath: process.env.LODCONVERT_CHROMIUM || "/usr/bin/chromium",
    args: FLAGS,
  });
  try {
    const page = await browser.newPage({ viewport: VIEWPORT });
    page.on("console", (m) => NOISE.test(m.text()) || log.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
    page.on("requestfailed", (r) => log.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
    page.on("response", (r) => r.status() >= 400 && log.push(`HTTP ${r.status()}: ${r.url()}`));
    const result = await scenarios[scenario](page);
    const renderer = await page.evaluate(() => {
      const gl = document.createElement("canvas").getContext("webgl2");
      const info = gl?.getExtension("WEBGL_debug_renderer_info");
      return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : "no WebGL 2";
    });
    return { ok: true, result, console: log, renderer };
  } finally {
    await browser.close();
  }
}

main().then(
  (out) => process.stdout.write(JSON.stringify(out) + "\n"),
  (error) => {
    process.stdout.write(JSON.stringify({ ok: false, error: String(error?.message ?? error), console: log }) + "\n");
    process.exitCode = 1;
  },
);
