// lodconvert viewer page, common part: the configuration written by lodconvert, the readout of
// each object's active level and distance and of each LOD parent (cell): open (its members
// shown), merged (its far level shown), culled, or hidden inside a coarser cell that is not
// open; the distance slider, the LOD scale (a factor on every cutoff the page switches at, from
// ?lodscale= in the URL or its field), the panel that shows the id and attributes of a clicked
// object, the alert box over the view (what failed to load: the viewer library, imported here
// first, or the model), and window.lodconvertViewer (state for tests and curious users,
// setDistance, setLodScale and screenPoint). The format part after it (gltf.js or x3d.js)
// defines a backend { load(host), setDistance(d), setLodScale(s), pick(event), highlight(index),
// screenPoint(point) } and calls start(backend); it reports the levels and distances of objects
// through update() and of cells through updateCell(). An object or cell inside a cell that is
// not open is not drawn by its own LOD, whose level the page then ignores (a viewer need not
// update it).

const config = JSON.parse(document.getElementById("lodconvert-config").textContent);
const readout = document.getElementById("readout");
const slider = document.getElementById("distance");
const status = document.getElementById("status");
const inspect = document.getElementById("inspect");
const cellReadout = document.getElementById("cells");
const lodScaleField = document.getElementById("lodscale");
const cells = config.cells;
const MAX_LISTED = 8;
const MAX_CELLS_LISTED = 12;
/** How far (CSS pixels) the pointer may move between press and release of a click: farther, it
 * is a drag of the view, which selects nothing. */
const CLICK_SLOP_PX = 4;

const most = (values) => values.reduce((a, b) => Math.max(a, b), -Infinity);
const least = (values) => values.reduce((a, b) => Math.min(a, b), Infinity);
const centers = config.objects.map((o) => o.center);
/** The viewer looks at the middle of the objects' centres from `distance` along `viewDirection`. */
const focus = [0, 1, 2].map((k) => {
  const values = centers.map((c) => c[k]);
  return (least(values) + most(values)) / 2;
});
/** Where the viewer stands from the focus: a unit vector (+z, tilted up for a y-up city). */
const viewDirection = config.view.direction;
/** The file's scene frame rotation, rows: an object's source axes → the scene's. */
const rotation = config.rotation;
/** `v` turned by the rotation (transposed: back into source axes). */
const turned = (v, transposed = false) => rotation.map((row, i) => {
  return row.reduce((sum, _, k) => sum + (transposed ? rotation[k][i] : row[k]) * v[k], 0);
});
/** Distance between the points `a` and `b`. */
const distanceBetween = (a, b) => Math.hypot(...a.map((v, k) => v - b[k]));
const offsets = centers.map((c) => distanceBetween(c, focus));
const cellOffsets = cells.map((cell) => distanceBetween(cell.center, focus));

/** The LOD scale: the factor on every cutoff the page switches at. */
let lodScale = 1;
const scaled = (cutoffs) => cutoffs.map((c) => c * lodScale);

// The slider spans half the smallest diagonal to twice the farthest reach of any object or cell
// (an object's last cutoff, or where its diagonal spans SMALLEST_PX of the reference view if
// that is farther — an object that keeps its mesh at every distance has no cutoff —; a cell's
// last cutoff; both scaled and plus the offset from the focus), logarithmically: at its end
// every object and cell is beyond its last cutoff. A new LOD scale moves its end.
const SMALLEST_PX = 16;
const focal = config.view.height_px / 2 / Math.tan((config.view.fov_y_deg * Math.PI) / 360);
const reachOf = (o) => most([(o.alpha * focal) / SMALLEST_PX, ...scaled(o.cutoffs)]);
const nearest = least(config.objects.map((o) => o.alpha)) / 2;
let farthest, span;
/** Set the slider's far end (and so its span) for the LOD scale. */
function spanSlider() {
  const reaches = [
    ...config.objects.map((o, i) => reachOf(o) + offsets[i]),
    ...cells.map((cell, i) => most(scaled(cell.cutoffs)) + cellOffsets[i]),
  ];
  farthest = 2 * most(reaches);
  span = Math.log(farthest / nearest);
}
const sliderDistance = (value) => nearest * Math.exp((span * value) / 1000);
const sliderValue = (distance) => (1000 * Math.log(distance / nearest)) / span;
/** The first view: every object whole in view (for one object, at 1.25 diagonals). */
const reach = most(config.objects.map((o, i) => o.alpha / 2 + offsets[i]));

/**
 * Index of the level `entry` (an object or a cell) shows at `distance` from its centre, at the
 * LOD scale (past the last: nothing).
 */
const levelAt = (entry, distance) => scaled(entry.cutoffs).filter((c) => c <= distance).length;

/**
 * The outermost of cell `index` and the cells holding it that does not show its members, its
 * level (`levelOf(i)`, null or negative while unknown) beyond 0; null when every one is open.
 */
function closedCell(index, levelOf) {
  let closed = null;
  for (let i = index; i !== null; i = cells[i].parent) if (levelOf(i) > 0) closed = i;
  return closed;
}
const CELL_STATES = ["open", "merged", "culled"];

const state = {
  ready: false,
  error: null,
  loadMs: null,
  // level: the name of the level it shows; cell: the id of the cell drawn in its place, if any
  objects: config.objects.map((o) => ({
    id: o.id, level: null, levelIndex: null, distance: null, cell: null,
  })),
  // per cell id: {state: open, merged, culled or hidden, level: its level when not hidden}
  cells: {},
  merged: 0, // cells showing their far level
  lodScale,
  distance: null, // of the viewer from the focus, once drawn there
  settled: false, // no move under way: the levels and distances shown are final
  selected: null, // id of the object whose attributes the panel shows
  clicks: 0, // clicks on the view handled (each selects an object or nothing)
  setDistance: null,
  setLodScale: null, // resolves once drawn at the new scale; false for a scale not positive
  screenPoint: null, // [x, y, z] in world coordinates → {x, y} in CSS pixels, or null
};
window.lodconvertViewer = state;

/** Name of level `index` of `object`: past the last level of a culled chain, nothing. */
function levelName(object, index) {
  return index < object.levels.length ? object.levels[index] : "nothing (culled)";
}

/** Levels and distances as the viewer reports them, per object and per cell. */
const reported = {
  objects: config.objects.map(() => ({ levelIndex: null, distance: null })),
  cells: cells.map(() => ({ levelIndex: null, distance: null })),
};
const known = (level) => (level !== null && level >= 0 ? level : null);

/** Set state.cells, state.merged and state.objects from the levels reported. */
function derive() {
  const levelOf = (i) => reported.cells[i].levelIndex;
  state.merged = 0;
  cells.forEach((cell, i) => {
    const { levelIndex, distance } = reported.cells[i];
    const hidden = cell.parent !== null && closedCell(cell.parent, levelOf) !== null;
    const level = hidden ? null : known(levelIndex);
    const name = hidden ? "hidden" : (CELL_STATES[level] ?? "…");
    state.cells[cell.id] = { state: name, level, distance };
    if (name === "merged") state.merged += 1;
  });
  config.objects.forEach((object, i) => {
    const { levelIndex, distance } = reported.objects[i];
    const closed = object.cell === null ? null : closedCell(object.cell, levelOf);
    const level = closed === null ? known(levelIndex) : null;
    Object.assign(state.objects[i], {
      level: level === null ? null : levelName(object, level),
      levelIndex: level,
      distance,
      cell: closed === null ? null : cells[closed].id,
    });
  });
}

const brief = (value) => (value === null ? "…" : value.toPrecision(4));
/** The cutoffs of `entry` (object or cell) at the LOD scale; an object of one level has none. */
function cutoffText(entry) {
  if (entry.cutoffs.length === 0) return "no cutoff";
  return `cutoffs ${scaled(entry.cutoffs).map(brief).join(" | ")}`;
}

/** Lines of the first `max` of `lines`, and one more counting the others as `what`. */
function listed(lines, max, what) {
  const shown = lines.slice(0, max);
  if (lines.length > max) shown.push(`… and ${lines.length - max} more ${what}`);
  return shown.join("\n");
}

function objectLine(o, i) {
  const shown = o.cell === null ? o.level ?? "…" : `${state.cells[o.cell].state} with ${o.cell}`;
  return `${o.id}: ${shown} at distance ${brief(o.distance)} (${cutoffText(config.objects[i])})`;
}

function cellLine(cell) {
  const { state: shown, distance } = state.cells[cell.id];
  return `${cell.id} (${cell.kind}): ${shown} at distance ${brief(distance)} (${cutoffText(cell)})`;
}

let readoutPending = false;

function showReadout() {
  readoutPending = false;
  derive();
  readout.textContent = listed(state.objects.map(objectLine), MAX_LISTED, "objects");
  if (cells.length === 0) return;
  const merged = `cells: ${state.merged} of ${cells.length} merged (showing their far level)`;
  cellReadout.textContent = `${merged}\n${listed(cells.map(cellLine), MAX_CELLS_LISTED, "cells")}`;
}

function scheduleReadout() {
  if (!readoutPending) {
    readoutPending = true;
    requestAnimationFrame(showReadout);
  }
}

/** Record object `index`'s active level (an index into its levels) and its distance. */
function update(index, levelIndex, distance) {
  Object.assign(reported.objects[index], { levelIndex, distance });
  scheduleReadout();
}

/** Record cell `index`'s active level (0 open, 1 merged, 2 culled) and its distance. */
function updateCell(index, levelIndex, distance) {
  Object.assign(reported.cells[index], { levelIndex, distance });
  scheduleReadout();
}

/**
 * Show the id and attributes of object `index` in the panel, with a button that deselects it;
 * null empties and hides it.
 */
function select(index) {
  const object = index === null ? null : config.objects[index];
  state.selected = object?.id ?? null;
  inspect.hidden = object === null;
  inspect.replaceChildren();
  if (object === null) return;
  const heading = document.createElement("h2");
  heading.textContent = object.id;
  const table = document.createElement("table");
  const { id, ...others } = object.attributes; // the id is the heading already
  addAttributes(table, id === object.id ? others : object.attributes);
  const close = document.createElement("button");
  Object.assign(close, { type: "button", className: "close", textContent: "×" });
  close.title = "Deselect";
  inspect.append(close, heading, table);
}

/**
 * Clicks on the view select the object under the pointer (or nothing): its attributes show in
 * the panel, and the backend highlights it in place of the one before; drags do not. The
 * panel's close button selects nothing.
 */
function watchClicks(backend, view) {
  const choose = (index) => {
    select(index);
    backend.highlight(index);
  };
  let pressed = null;
  view.addEventListener("pointerdown", (event) => { pressed = [event.clientX, event.clientY]; });
  view.addEventListener("click", (event) => {
    if (pressed === null) return;
    if (Math.hypot(event.clientX - pressed[0], event.clientY - pressed[1]) > CLICK_SLOP_PX) return;
    choose(backend.pick(event));
    state.clicks += 1;
  });
  inspect.addEventListener("click", (event) => {
    if (event.target.closest("button.close")) choose(null);
  });
}

/** Show `error` (an Error or a message) in the alert box, as the page's error. */
function fail(error) {
  state.error = String(error?.message ?? error);
  alertBox(state.error);
  console.error(error);
}

/** A failure to load what the page shows, its message naming what failed for the user. */
class LoadFailure extends Error {}

/** The file name of the asset the page shows. */
const assetName = () => decodeURIComponent(config.asset.split("/").pop());

/** How to give the page a viewer library it can reach (lines of the alert box). */
function localLibraryHint() {
  const { package: name, version } = config.library;
  return "Re-run lodconvert with --viewer-lib DIR, DIR a local copy of the npm package " +
    `${name}@${version} (npm install ${name}@${version} puts one in node_modules/${name}) ` +
    "inside this page's folder, or serve both:\n" +
    `lodconvert view ${assetName()} --serve --viewer-lib DIR`;
}

/** Seconds the viewer library may take to load before the page says where it waits. */
const SLOW_LIBRARY_S = 10;

/**
 * Import the modules of the viewer library the page's import map names (the backend imports
 * them again from the cache): the readout says which one it waits for and, after
 * SLOW_LIBRARY_S, the alert box how to do without it; one that fails to load throws a
 * LoadFailure naming its URL.
 */
async function importLibrary() {
  const { imports } = JSON.parse(document.querySelector('script[type="importmap"]').textContent);
  const modules = Object.entries(imports).filter(([name]) => !name.endsWith("/"));
  for (const [name, relative] of modules) {
    const url = new URL(relative, location.href);
    const where = url.origin === location.origin ? "" : " (offline, or its host blocked?)";
    readout.textContent = `loading the viewer library ${url} …`;
    const slow = setTimeout(() => {
      alertBox(`Still waiting for the viewer library\n${url}${where}\n\n${localLibraryHint()}`);
    }, SLOW_LIBRARY_S * 1000);
    try {
      await import(name);
    } catch (error) {
      console.error(error);
      const failed = `Could not load the viewer library\n${url}${where}`;
      throw new LoadFailure(`${failed}\n\n${localLibraryHint()}`);
    } finally {
      clearTimeout(slow);
    }
  }
  alertBox(null);
  readout.textContent = `loading ${assetName()} …`;
}

/**
 * The message for `error`, thrown while loading the library or the model: the model's URL and
 * why it could not be fetched, when it cannot.
 */
async function loadFailure(error) {
  if (error instanceof LoadFailure) return error.message;
  const url = new URL(config.asset, location.href);
  const response = await fetch(url, { method: "HEAD", cache: "no-store" }).catch(() => null);
  const text = String(error?.message ?? error);
  if (response?.ok) return `Could not show the model\n${url}\n${text}`;
  const why = response ? `HTTP ${response.status} ${response.statusText}`.trim() : "unreachable";
  return `Could not load the model\n${url} (${why})\n\nIt must lie where it was when the ` +
    `page was written, in the folder served:\nlodconvert view ${assetName()} --serve`;
}

/** Two animation frames: whatever was changed before has been drawn. */
const nextFrame = () => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)));

let moves = 0;

/** Move the viewer to `distance` from the focus; resolves once it is drawn there. */
async function moveTo(backend, distance) {
  const move = ++moves;
  state.settled = false;
  await backend.setDistance(distance);
  if (move === moves) {
    showReadout(); // the state is final before it is declared settled
    state.distance = distance;
    state.settled = true;
  }
}

const positive = (value) => Number.isFinite(value) && value > 0;

/** The LOD scale the page's URL asks for (?lodscale=2), 1 when it asks for none. */
function urlLodScale() {
  const text = new URLSearchParams(location.search).get("lodscale");
  if (text === null) return 1;
  if (positive(Number(text))) return Number(text);
  status.textContent = `lodscale=${text} in the URL is not a positive number: the scale is 1.`;
  return 1;
}

/** Take `scale` as the LOD scale in the page's state, its field and the slider's span. */
function applyLodScale(scale) {
  lodScale = state.lodScale = scale;
  lodScaleField.value = String(scale);
  spanSlider();
}

/**
 * Switch at `scale` times every cutoff; resolves once drawn so. A scale that is not positive
 * changes nothing (the field shows the scale again) and resolves to false.
 */
async function setLodScale(backend, scale) {
  if (!positive(scale)) {
    lodScaleField.value = String(lodScale);
    return false;
  }
  applyLodScale(scale);
  backend.setLodScale(scale);
  slider.value = String(sliderValue(state.distance));
  await moveTo(backend, state.distance);
  return true;
}

async function start(backend) {
  if (location.protocol === "file:") {
    fail(`Browsers do not let a page opened from a file load ${config.asset}: ` +
         `serve this folder (lodconvert view ${config.asset} --serve) and open the URL it prints.`);
    return;
  }
  try {
    const started = performance.now();
    const view = document.getElementById("view");
    applyLodScale(urlLodScale());
    cellReadout.hidden = cells.length === 0;
    await importLibrary();
    await backend.load(view);
    if (lodScale !== 1) backend.setLodScale(lodScale);
    watchClicks(backend, view);
    state.screenPoint = (point) => backend.screenPoint(point);
    state.setDistance = async (distance) => {
      slider.value = String(sliderValue(distance));
      await moveTo(backend, distance);
    };
    slider.addEventListener("input", () => {
      moveTo(backend, sliderDistance(Number(slider.value))).catch(fail);
    });
    await state.setDistance(Math.min(farthest, 2.5 * reach)); // the overview
    state.setLodScale = (scale) => setLodScale(backend, scale);
    lodScaleField.addEventListener("change", () => {
      setLodScale(backend, Number(lodScaleField.value)).catch(fail);
    });
    state.loadMs = performance.now() - started;
    state.ready = true;
  } catch (error) {
    readout.textContent = "not shown: see the message over the view";
    fail(await loadFailure(error));
  }
}
