#!/usr/bin/env node
// Drive X_ITE through an X3D file's prism switching in headless Chromium and print, as one line
// of JSON, which level each object showed at each stop; its output, waits and hang guard are
// those of harness.mjs (see there), its command line names no scenario (it has one):
//
//   node tests/browser/prism.mjs BASE_URL PARAMS_JSON
//
// PARAMS: file (the .x3d, in the site), objects ([{base, switches}]: an object's DEF base and
// its number of prism Switches), stops ([{position, expected}]: where to put the viewer, world
// coordinates, or no position for the viewer X_ITE starts with; and the level each object
// should show there), safety_ms. At a stop, frames are drawn until every object shows its
// expected level, or SETTLE_FRAMES frames (a count, not a time: a slow machine waits longer);
// the levels shown then are reported, read from the Switches' whichChoice: an object shows level
// k for the first Switch k at its near choice (0), its last level (or nothing, culled) when none
// is. Result: {"stops": [[{level, choices}, ...], ...]}.

import { evaluate, openTestPage, run } from "./harness.mjs";

const SETTLE_FRAMES = 120;

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

/** The one scenario: load params.file in X_ITE and read the objects' levels at params.stops. */
async function switching(page, { base, params }) {
  await openTestPage(page, base, "x_ite", "X_ITE");
  const load = (url) => window.harness.load(url, []);
  await evaluate(page, `X_ITE loading ${params.file}`, load, `${base}/${params.file}`);
  const stops = [];
  for (const stop of params.stops) {
    if (stop.position) {
      const place = (p) => window.harness.place(p);
      await evaluate(page, `placing the viewer at ${stop.position}`, place, stop.position);
    }
    const what = `X_ITE settling at ${stop.position ?? "its start"}`;
    const arg = { objects: params.objects, expected: stop.expected, frames: SETTLE_FRAMES };
    stops.push(await evaluate(page, what, settle, arg));
  }
  return { stops };
}

run({ switching }, { argv: ["switching", ...process.argv.slice(2)] });
