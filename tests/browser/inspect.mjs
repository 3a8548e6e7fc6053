#!/usr/bin/env node
// Click objects on lodconvert's viewer page in headless Chromium and print what its inspect panel
// showed as one line of JSON; its command line, output, waits and hang guard are those of
// harness.mjs (see there):
//
//   node tests/browser/inspect.mjs clicks BASE_URL PARAMS_JSON
//
// PARAMS: {page, clicks: [{point} or {at}]}: the page is clicked, in turn, where the world point
// `point` shows (the page's lodconvertViewer.screenPoint) or at `at`, fractions of the view's
// width and height, with the viewer where the page first puts it. The readout panel is hidden
// first: it covers part of the view, and a click on it is not one on the view. Result per click:
// the pixel clicked, the object selected, and the inspect panel (hidden, its heading and its rows
// as [header, cell or null]). Every wait is on page state.

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
async function clicks(page, { base, params }) {
  await openViewer(page, base, params.page);
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

run({ clicks });
