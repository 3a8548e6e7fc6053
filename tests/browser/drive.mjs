#!/usr/bin/env node
// Drive a web3D viewer (X_ITE, X3DOM, Babylon.js, three.js or lodconvert's viewer page) in
// headless Chromium and print what it saw as one line of JSON, with the WebGL renderer's name;
// its command line, output, waits and hang guard are those of harness.mjs (see there):
//
//   node tests/browser/drive.mjs SCENARIO BASE_URL PARAMS_JSON
//
// SCENARIO: x_ite, x3dom, babylon, three, three_upright or viewer (PARAMS: see each below).

import { doing, evaluate, openTestPage, openViewer, run, waitFor } from "./harness.mjs";

/**
 * Pixels of the element `selector` that differ from the background (by more than 24 in a
 * channel; the background is the top-left pixel unless given): their number, `foreground`,
 * their mean brightness (Rec. 709 luma, 0-255; null without any), `brightness`, their mean
 * colour, `mean`, and the mean of their three channels' standard deviations, `spread`. The
 * screenshot is decoded in the page itself.
 */
async function pixels(page, selector, background = null) {
  doing(`screenshot of ${selector}`);
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
      const sums = [0, 0, 0];
      const squares = [0, 0, 0];
      for (let i = 0; i < rgba.length; i += 4) {
        if ([0, 1, 2].some((k) => Math.abs(rgba[i + k] - bg[k]) > 24)) {
          count += 1;
          luma += 0.2126 * rgba[i] + 0.7152 * rgba[i + 1] + 0.0722 * rgba[i + 2];
          for (const k of [0, 1, 2]) {
            sums[k] += rgba[i + k];
            squares[k] += rgba[i + k] * rgba[i + k];
          }
        }
      }
      const spread = count
        ? [0, 1, 2].map((k) => Math.sqrt(Math.max(squares[k] / count - (sums[k] / count) ** 2, 0)))
          .reduce((a, b) => a + b) / 3
        : null;
      const mean = count ? sums.map((v) => v / count) : null;
      return { foreground: count, brightness: count ? luma / count : null, spread, mean };
    },
    { data: png.toString("base64"), background },
  );
}

const scenarios = {
  /**
   * X_ITE: load params.file (with params.start, screenshot the view it starts with: the file's
   * own Viewpoint), then per stop place the viewer and read params.lod's level.
   */
  async x_ite(page, { base, params }) {
    await openTestPage(page, base, "x_ite", "X_ITE");
    const firstFrameMs = await evaluate(page, `X_ITE loading ${params.file}`,
      ([url, lods]) => window.harness.load(url, lods),
      [`${base}/${params.file}`, params.lod ? [params.lod] : []],
    );
    const start = params.start ? await pixels(page, "x3d-canvas") : null;
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
    return { firstFrameMs, start, stops };
  },

  /** X3DOM: load params.file in an Inline, wait until it is drawn, collect X3DOM's log. */
  async x3dom(page, { base, params }) {
    doing("loading the X3DOM test page");
    const file = encodeURIComponent(`${base}/${params.file}`);
    await page.goto(`${base}/pages/x3dom.html?file=${file}`);
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
  async babylon(page, { base, params }) {
    await openTestPage(page, base, "babylon", "Babylon.js");
    const result = await evaluate(page, `Babylon.js loading ${params.file}`,
      ([url, maxLods]) => window.harness.load(url, maxLods),
      [`${base}/${params.file}`, params.maxLods ?? null],
    );
    return { ...result, ...(await pixels(page, "canvas")) };
  },

  /** three.js: load params.file and draw node params.node alone. */
  async three(page, { base, params }) {
    await openTestPage(page, base, "three", "three.js");
    const result = await evaluate(page, `three.js loading ${params.file}`,
      ([url, node]) => window.harness.show(url, node),
      [`${base}/${params.file}`, params.node],
    );
    return { ...result, ...(await pixels(page, "canvas")) };
  },

  /** three.js, plainly: load params.file and draw its scene from straight above (+Y). */
  async three_upright(page, { base, params }) {
    await openTestPage(page, base, "three_upright", "three.js");
    return evaluate(page, `three.js loading ${params.file}`,
      (url) => window.harness.fromAbove(url), `${base}/${params.file}`);
  },

  /**
   * lodconvert's viewer page params.page: per stop move the viewer, by setDistance(distance) or
   * by pressing `key` on the distance slider, and read every object's state once drawn there
   * (with `shot`, the page is saved there as a PNG first).
   */
  async viewer(page, { base, params }) {
    await openViewer(page, base, params.page);
    const stops = [];
    for (const stop of params.stops) {
      if (stop.key === undefined) {
        const move = (d) => window.lodconvertViewer.setDistance(d);
        await evaluate(page, `moving to ${stop.distance}`, move, stop.distance);
      } else {
        doing(`pressing ${stop.key} on the slider`);
        await page.locator("#distance").press(stop.key);
        const settled = () => window.lodconvertViewer.settled;
        await waitFor(page, `moving after ${stop.key} on the slider`, settled);
      }
      if (stop.shot) {
        doing(`saving a screenshot at ${stop.distance}`);
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

run(scenarios, { renderer: true });
