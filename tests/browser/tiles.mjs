#!/usr/bin/env node
// Look at a 3D Tiles tileset through lodconvert's CesiumJS page (lodconvert view
// DIR/tileset.json) in headless Chromium from given cameras and print, per camera, the tiles
// CesiumJS selected and the bytes it requested, as one line of JSON; its command line, output,
// waits and hang guard are those of harness.mjs (see there):
//
//   node tests/browser/tiles.mjs cameras BASE_URL PARAMS_JSON
//
// PARAMS: {page: the page's path on the server, cameras: [{name, target: [x, y, z] (ECEF
// metres; default the tileset's centre), range (metres), heading, pitch (degrees), click:
// whether to click at the target, shot: a PNG path, taken after the click}]}. Each camera loads the page afresh, its URL
// setting the view, so that what it requested is what that view needs: the page settles (every
// tile of the view loaded and drawn), then its state is read. Result per camera: name,
// tilesSelected, tiles ([{uri, kind, geometricError}]), bytes (content bytes requested: tile
// .glb and .json files, the page's tileset.json included), requests (their number), failed
// (tiles that failed to load) and, with click, what the click picked and the inspect panel's
// heading and rows; with a target, where it shows (`at`: CSS pixels). benchmarks call it too
// (tilesbench).

import { doing, evaluate, run, waitFor } from "./harness.mjs";

/** The page's URL for `camera`. */
function viewUrl(base, page, camera) {
  const query = new URLSearchParams();
  if (camera.target) query.set("target", camera.target.join(","));
  for (const name of ["range", "heading", "pitch"]) {
    if (camera[name] !== undefined) query.set(name, String(camera[name]));
  }
  return `${base}/${page}?${query}`;
}

/** What the inspect panel shows. */
const panel = () => {
  const inspect = document.getElementById("inspect");
  return {
    hidden: inspect.hidden,
    heading: inspect.querySelector("h2")?.textContent ?? null,
    rows: [...inspect.querySelectorAll("tr")].map((row) =>
      [row.querySelector("th").textContent, row.querySelector("td")?.textContent ?? null]),
  };
};

/** Click the view where the world point `point` shows; resolves once the page handled it. */
async function clickAt(page, point) {
  const at = await evaluate(page, `projecting ${point}`,
    (p) => window.lodconvertViewer.screenPoint(p), point);
  if (at === null) throw new Error(`${point} is not in view`);
  await evaluate(page, "hiding the readout panel", () => {
    document.getElementById("panel").style.visibility = "hidden";
  });
  const before = await evaluate(page, "counting clicks", () => window.lodconvertViewer.clicks);
  doing(`clicking at (${at.x}, ${at.y})`);
  await page.mouse.click(Math.floor(at.x) + 0.5, Math.floor(at.y) + 0.5);
  await waitFor(page, "the page handling the click",
    (n) => window.lodconvertViewer.clicks > n, before);
  await evaluate(page, "showing the readout panel", () => {
    document.getElementById("panel").style.visibility = "";
  });
}

/** One camera on the page loaded afresh: what it selected and requested. */
async function look(page, base, params, camera) {
  const requested = [];
  const count = (response) => {
    const path = new URL(response.url()).pathname;
    if (/\.(glb|json)$/.test(path) && !path.includes("/node_modules/")) {
      requested.push(Number(response.headers()["content-length"] ?? 0));
    }
  };
  page.on("response", count);
  try {
    doing(`opening ${params.page} for the camera ${camera.name}`);
    await page.goto(viewUrl(base, params.page, camera));
    await waitFor(page, `the page settling for the camera ${camera.name}`, () => {
      return window.lodconvertViewer?.ready || window.lodconvertViewer?.error;
    });
    const error = await evaluate(page, "reading its error", () => window.lodconvertViewer.error);
    if (error) throw new Error(`viewer page: ${error}`);
    const seen = await evaluate(page, "reading the tiles", () => {
      const { tiles, failed } = window.lodconvertViewer;
      return { tiles, failed, readout: document.getElementById("readout").textContent };
    });
    const bytes = requested.reduce((a, b) => a + b, 0);
    const out = { name: camera.name, tilesSelected: seen.tiles.length, ...seen, bytes,
      requests: requested.length };
    if (camera.target) {
      out.at = await evaluate(page, `projecting ${camera.target}`,
        (p) => window.lodconvertViewer.screenPoint(p), camera.target);
    }
    if (camera.click) {
      await clickAt(page, camera.target);
      out.picked = await evaluate(page, "reading the pick", () => window.lodconvertViewer.picked);
      out.panel = await evaluate(page, "reading the inspect panel", panel);
    }
    if (camera.shot) {
      doing(`saving a screenshot for the camera ${camera.name}`);
      await page.screenshot({ path: camera.shot });
    }
    return out;
  } finally {
    page.off("response", count);
  }
}

/** The one scenario: each of params.cameras in turn. */
async function cameras(page, { base, params }) {
  const seen = [];
  for (const camera of params.cameras) seen.push(await look(page, base, params, camera));
  return { cameras: seen };
}

run({ cameras });
