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
// the inspect panel's close button (`close`: true; the pixel is null then). The
// readout panel is hidden first: it covers part of the view, and a click on it is not one on the
// view. Result: the colour (RGB) where each probe shows before the clicks, and per click the
// pixel clicked, the object selected, the inspect panel (hidden, its heading and its rows as
// [header, cell or null]) and the probes' colours after it. Every wait is on page state.

import { doing, evaluate, openViewer, run, waitFor } from "./harness.mjs";

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
  doing(`clicking at (${x}, ${y})`);
  await page.mouse.click(x, y);
  const handled = (n) => window.lodconvertViewer.clicks > n;
  await waitFor(page, "the page handling the click", handled, before);
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
 * The colour (mean RGB of the 3 × 3 pixels around it) of the view at each of `pixels` (CSS),
 * once what changed has been drawn; the inspect panel is hidden meanwhile.
 */
async function coloursAt(page, pixels) {
  const inspect = (shown) => { document.getElementById("inspect").style.visibility = shown; };
  await evaluate(page, "hiding the inspect panel", inspect, "hidden");
  await evaluate(page, "drawing two frames", () => new Promise((done) => {
    requestAnimationFrame(() => requestAnimationFrame(done));
  }));
  doing("taking a screenshot");
  const png = await page.screenshot();
  await evaluate(page, "showing the inspect panel", inspect, "");
  return evaluate(page, "reading the screenshot", async ({ data, pixels }) => {
    const bytes = Uint8Array.from(atob(data), (c) => c.charCodeAt(0));
    const bitmap = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
    const context = new OffscreenCanvas(bitmap.width, bitmap.height).getContext("2d");
    context.drawImage(bitmap, 0, 0);
    return pixels.map(({ x, y }) => {
      const rgba = context.getImageData(Math.round(x) - 1, Math.round(y) - 1, 3, 3).data;
      return [0, 1, 2].map((k) => rgba.filter((_, i) => i % 4 === k).reduce((a, b) => a + b) / 9);
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
