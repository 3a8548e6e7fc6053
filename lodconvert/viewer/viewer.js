// lodconvert viewer page, common part: the configuration written by lodconvert, the readout of
// each object's active level and distance, the distance slider, the panel that shows the id and
// attributes of a clicked object, and window.lodconvertViewer (state for tests and curious
// users, setDistance and screenPoint). The format part after it (gltf.js or x3d.js) defines a
// backend { load(host), setDistance(d), pick(event), screenPoint(point) } and calls
// start(backend); it reports levels and distances through update().

const config = JSON.parse(document.getElementById("lodconvert-config").textContent);
const readout = document.getElementById("readout");
const slider = document.getElementById("distance");
const status = document.getElementById("status");
const inspect = document.getElementById("inspect");
const MAX_LISTED = 8;
/** How far (CSS pixels) the pointer may move between press and release of a click: farther, it
 * is a drag of the view, which selects nothing. */
const CLICK_SLOP_PX = 4;

const most = (values) => values.reduce((a, b) => Math.max(a, b), -Infinity);
const least = (values) => values.reduce((a, b) => Math.min(a, b), Infinity);
const centers = config.objects.map((o) => o.center);
/** The viewer looks at the middle of the objects' centres from `distance` along +z. */
const focus = [0, 1, 2].map((k) => {
  const values = centers.map((c) => c[k]);
  return (least(values) + most(values)) / 2;
});
const offsets = centers.map((c) => Math.hypot(...c.map((v, k) => v - focus[k])));

// The slider spans half the smallest diagonal to twice the farthest reach of any object
// (its last cutoff, or where its diagonal spans SMALLEST_PX of the reference view if that is
// farther — an object that keeps its mesh at every distance has no cutoff —, plus its offset
// from the focus), logarithmically: at its end every object is beyond its last cutoff.
const SMALLEST_PX = 16;
const focal = config.view.height_px / 2 / Math.tan((config.view.fov_y_deg * Math.PI) / 360);
const reachOf = (o) => most([(o.alpha * focal) / SMALLEST_PX, ...o.cutoffs]);
const nearest = least(config.objects.map((o) => o.alpha)) / 2;
const farthest = 2 * most(config.objects.map((o, i) => reachOf(o) + offsets[i]));
const span = Math.log(farthest / nearest);
const sliderDistance = (value) => nearest * Math.exp((span * value) / 1000);
const sliderValue = (distance) => (1000 * Math.log(distance / nearest)) / span;
/** The first view: every object whole in view (for one object, at 1.25 diagonals). */
const reach = most(config.objects.map((o, i) => o.alpha / 2 + offsets[i]));
const overview = Math.min(farthest, 2.5 * reach);

/** Index of the level `object` shows at `distance` from its centre (past the last: nothing). */
const levelAt = (object, distance) => object.cutoffs.filter((c) => c <= distance).length;

const state = {
  ready: false,
  error: null,
  loadMs: null,
  objects: config.objects.map((o) => ({ id: o.id, level: null, levelIndex: null, distance: null })),
  distance: null, // of the viewer from the focus, once drawn there
  settled: false, // no move under way: the levels and distances shown are final
  selected: null, // id of the object whose attributes the panel shows
  clicks: 0, // clicks on the view handled (each selects an object or nothing)
  setDistance: null,
  screenPoint: null, // [x, y, z] in world coordinates → {x, y} in CSS pixels, or null
};
window.lodconvertViewer = state;

/** Name of level `index` of `object`: past the last level of a culled chain, nothing. */
function levelName(object, index) {
  return index < object.levels.length ? object.levels[index] : "nothing (culled)";
}

let readoutPending = false;

function showReadout() {
  readoutPending = false;
  const lines = state.objects.slice(0, MAX_LISTED).map((o, i) => {
    const cutoffs = config.objects[i].cutoffs.map((c) => c.toPrecision(4)).join(" | ");
    const distance = o.distance === null ? "…" : o.distance.toPrecision(4);
    return `${o.id}: ${o.level ?? "…"} at distance ${distance} (cutoffs ${cutoffs})`;
  });
  if (state.objects.length > MAX_LISTED) lines.push(`… and ${state.objects.length - MAX_LISTED} more objects`);
  readout.textContent = lines.join("\n");
}

/** Record object `index`'s active level (an index into its levels) and its distance. */
function update(index, levelIndex, distance) {
  const object = state.objects[index];
  object.levelIndex = levelIndex;
  object.level = levelIndex === null ? null : levelName(config.objects[index], levelIndex);
  object.distance = distance;
  if (!readoutPending) {
    readoutPending = true;
    requestAnimationFrame(showReadout);
  }
}

const isRecord = (value) => value !== null && typeof value === "object" && !Array.isArray(value);

/** A row of `body` headed by `name` (its cell `text`, or the whole row without text). */
function addRow(body, name, text = null) {
  const row = body.insertRow();
  const header = document.createElement("th");
  header.textContent = name;
  header.scope = text === null ? "rowgroup" : "row";
  header.colSpan = text === null ? 2 : 1;
  row.append(header);
  if (text !== null) row.insertCell().textContent = text;
}

/**
 * Add `attributes` to `table`: a body with a row per plain attribute (strings as they are,
 * other values as JSON), then a body per nested object, headed by its (dotted) `name`.
 */
function addAttributes(table, attributes, name = null) {
  const body = table.createTBody();
  if (name !== null) addRow(body, name);
  const entries = Object.entries(attributes);
  for (const [key, value] of entries.filter(([, v]) => !isRecord(v))) {
    addRow(body, key, typeof value === "string" ? value : JSON.stringify(value));
  }
  for (const [key, value] of entries.filter(([, v]) => isRecord(v))) {
    addAttributes(table, value, name === null ? key : `${name}.${key}`);
  }
}

/** Show the id and attributes of object `index` in the panel; null empties and hides it. */
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
  inspect.append(heading, table);
}

/** Clicks on the view select the object under the pointer (or nothing); drags do not. */
function watchClicks(backend, view) {
  let pressed = null;
  view.addEventListener("pointerdown", (event) => { pressed = [event.clientX, event.clientY]; });
  view.addEventListener("click", (event) => {
    if (pressed === null) return;
    if (Math.hypot(event.clientX - pressed[0], event.clientY - pressed[1]) > CLICK_SLOP_PX) return;
    select(backend.pick(event));
    state.clicks += 1;
  });
}

function fail(error) {
  state.error = String(error?.message ?? error);
  status.textContent = state.error;
  console.error(error);
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
    state.distance = distance;
    state.settled = true;
  }
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
    await backend.load(view);
    watchClicks(backend, view);
    state.screenPoint = (point) => backend.screenPoint(point);
    state.setDistance = async (distance) => {
      slider.value = String(sliderValue(distance));
      await moveTo(backend, distance);
    };
    slider.addEventListener("input", () => {
      moveTo(backend, sliderDistance(Number(slider.value))).catch(fail);
    });
    await state.setDistance(overview);
    state.loadMs = performance.now() - started;
    state.ready = true;
  } catch (error) {
    fail(error);
  }
}
