#!/usr/bin/env node
// Move lodconvert's viewer page through distances and LOD scales in headless Chromium and print
// what it showed of its objects and LOD parents (cells) as one line of JSON; its command line,
// output, waits and hang guard are those of harness.mjs (see there):
//
//   node tests/browser/hlod.mjs stops BASE_URL PARAMS_JSON
//
// PARAMS: {page (with its query, e.g. "d.x3d.html?lodscale=2"), stops: [{distance} or {key} or
// {lodScale}]}: per stop the page is moved by setDistance(distance), by pressing `key` on the
// distance slider, or given a new LOD scale (setLodScale, or typed into its field with
// `typed`), and read once settled: distance, lodScale, objects, cells, merged and the text of
// the readouts. Every wait is on page state.

import { doing, evaluate, openViewer, run, waitFor } from "./harness.mjs";

/** Make one stop's move: resolves once the page has settled after it. */
async function move(page, stop) {
  if (stop.distance !== undefined) {
    const to = (d) => window.lodconvertViewer.setDistance(d);
    await evaluate(page, `moving to ${stop.distance}`, to, stop.distance);
    return;
  }
  if (stop.key !== undefined) {
    doing(`pressing ${stop.key} on the slider`);
    await page.locator("#distance").press(stop.key);
  } else if (stop.typed) {
    doing(`typing the LOD scale ${stop.lodScale}`);
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
async function stops(page, { base, params }) {
  await openViewer(page, base, params.page);
  const seen = [await evaluate(page, "reading the first view", shown)];
  for (const stop of params.stops) {
    await move(page, stop);
    seen.push(await evaluate(page, "reading the page", shown));
  }
  return { stops: seen };
}

run({ stops });
