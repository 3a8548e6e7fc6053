#!/usr/bin/env node
// Click objects on lodconvert's viewer page in headless Chromium and print what its inspect panel
// showed as one line of JSON; its command line, output, waits and hang guard are those of
// harness.mjs (see there):
//
//   node tests/browser/inspect.mjs clicks BASE_URL PARAMS_JSON
//
// PARAMS: {page, clicks: [{point} or {at} or {close}], probes: [point]}: the page is clicked, in
// turn, where the world point `point` shows (the page's lodconvertViewer.screenPoint), at `at`,
// fractions of the view's width and height, with the viewer where the page first puts it, or on
// the inspect panel's close button (`close`: true; the pixel is null then). The readout panel is
// hidden first, and the inspect panel while the view is clicked or read: they cover part of the
// view, and a click on them is not one on the view. Result: the colour (RGB) where each probe
// shows before the clicks, and per click the pixel clicked, the object selected, the inspect
// panel (hidden, its heading and its rows as [header, cell or null]) and the probes' colours
// after it. Every wait is on page state.

import { doing, evaluate, openViewer, run, waitFor } from "./harness.mjs";

/**
 * The page pixel (CSS) of `click`, where its world point shows or its fraction of the view: the
 * centre of the pixel there.
 */
async function pixelOf(page, click) {
  const at = click.point === undefined
    ? await evaluate(page, `finding ${click.at} of the view`, ([fx, fy]) => {
      const rect = document.getElementById("view").getBoundingClientRect();
      return { x: rect.left + fx * rect.width, y: rect.top + fy * rect.height };
    }, click.at)
    : await evaluate(page, `projecting ${click.point}`,
      (point) => window.lodconvertViewer.screenPoint(point), click.point);
  if (at === null) throw new Error(`${click.point} is behind the viewer`);
  return { x: Math.floor(at.x) + 0.5, y: Math.floor(at.y) + 0.5 };
}

/** In the page: show (`shown` "") or hide ("hidden") the inspect panel. */
const showInspect = (shown) => { document.getElementById("inspect").style.visibility = shown; };

/**
 * Click the view at `pixel`, the inspect panel hidden meanwhile (it covers part of the view);
 * resolves once the page handled the click.
 */
async function clickView(page, { x, y }) {
  await evaluate(page, "hiding the inspect panel", showInspect, "hidden");
  const covered = await evaluate(page, "checking what is at the pixel", ([x, y]) => {
    const element = document.elementFromPoint(x, y);
    return document.getElementById("view").contains(element) ? null : String(element?.outerHTML);
  }, [x, y]);
  if (covered !== null) throw new Error(`(${x}, ${y}) is on ${covered.slice(0, 80)}, not the view`);
  const before = await evaluate(page, "counting clicks", () => window.lodconvertViewer.clicks);
  doing(`clicking at (${x}, ${y})`);
  await page.mouse.click(x, y);
  const handled = (n) => window.lodconvertViewer.clicks > n;
  await waitFor(page, "the page handling the click", handled, before);
  await evaluate(page, "showing the inspect panel", showInspect, "");
}

/** Click the inspect panel's close button; resolves once the page selects nothing. */
async function closePanel(page) {
  doing("clicking the inspect panel's close button");
  await page.locator("#inspect button.close").click();
  await waitFor(page, "the page deselecting", () => window.lodconvertViewer.selected === null);
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

/**
 * The colour (RGB) of the view at each of `pixels` (CSS), once what changed has been drawn; the
 * inspect panel is hidden meanwhile.
 */
async function coloursAt(page, pixels) {
  await evaluate(page, "hiding the inspect panel", showInspect, "hidden");
  await evaluate(page, "drawing two frames", () => new Promise((done) => {
    requestAnimationFrame(() => requestAnimationFrame(done));
  }));
  doing("taking a screenshot");
  const png = await page.screenshot();
  await evaluate(page, "showing the inspect panel", showInspect, "");
  return evaluate(page, "reading the screenshot", async ({ data, pixels }) => {
    const bytes = Uint8Array.from(atob(data), (c) => c.charCodeAt(0));
    const bitmap = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
    const context = new OffscreenCanvas(bitmap.width, bitmap.height).getContext("2d");
    context.drawImage(bitmap, 0, 0);
    return pixels.map(({ x, y }) => {
      return [...context.getImageData(Math.floor(x), Math.floor(y), 1, 1).data.slice(0, 3)];
    });
  }, { data: png.toString("base64"), pixels });
}

/** The one scenario: open params.page and make params.clicks. */
async function clicks(page, { base, params }) {
  await openViewer(page, base, params.page);
  await evaluate(page, "hiding the readout panel", () => {
    document.getElementById("panel").style.visibility = "hidden";
  });
  const probes = [];
  for (const point of params.probes ?? []) probes.push(await pixelOf(page, { point }));
  const before = await coloursAt(page, probes);
  const seen = [];
  for (const click of params.clicks) {
    const pixel = click.close ? null : await pixelOf(page, click);
    if (pixel === null) await closePanel(page);
    else await clickView(page, pixel);
    const shown = await evaluate(page, "reading the inspect panel", panel);
    seen.push({ pixel, ...shown, probes: await coloursAt(page, probes) });
  }
  return { probes: before, clicks: seen };
}

run({ clicks });
