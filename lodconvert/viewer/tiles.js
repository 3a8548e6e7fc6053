// Tileset part: CesiumJS (a plain CesiumWidget: no Ion token, no imagery, no terrain but the
// ellipsoid) streams the 3D Tiles tileset with maximumScreenSpaceError = the --sse its
// geometricError was made for and, for point tiles, the pointCloudShading that sizes them as
// baked. The readout counts the tiles selected in the last frame by kind (far levels of LOD
// parents, blocks, leaves) and names the tile under the pointer; clicking a building shows its
// id and attributes (its feature's properties) and tints it. window.lodconvertViewer holds the
// state (`tiles`: the tiles selected, `failed`: tiles that failed to load, `selected`, `picked`,
// `settled`: the view's tiles loaded and drawn) and setCamera / screenPoint. ?target=X,Y,Z (ECEF metres) &range= &heading=
// &pitch= (degrees) in the URL set the first view, else it frames the whole tileset from the
// south, 35° above the horizon. The light comes from above the camera (not from the sun at the
// clock's time).

const config = JSON.parse(document.getElementById("lodconvert-config").textContent);
const readout = document.getElementById("readout");
const inspect = document.getElementById("inspect");
const PITCH_DEG = -35;
/** How far (CSS pixels) the pointer may move between press and release of a click. */
const CLICK_SLOP_PX = 4;
const HIGHLIGHT = "#ff9900";
/** The light's intensity (CesiumJS's diffuse term is the colour / π times it): a roof seen from
 * 35° to 60° above shows within a few levels of its own colour, as the three.js page shows it. */
const LIGHT_INTENSITY = 3;
let Cesium, widget, tileset, highlighted = null;

const state = {
  ready: false,
  error: null,
  loadMs: null,
  tiles: [], // {uri, kind, geometricError} of the tiles selected in the last frame drawn
  failed: [], // {uri, message} of tiles that failed to load
  settled: false, // the tiles of the current view are loaded and drawn
  selected: null, // id of the building whose attributes the panel shows
  picked: null, // what the last click picked: {id, properties, uri, kind} or {uri, kind}
  clicks: 0,
  setCamera: null, // ({target, range, heading, pitch}) → resolves once settled there
  screenPoint: null, // [x, y, z] ECEF → {x, y} CSS pixels, or null
};
window.lodconvertViewer = state;

/** The tile kind its content file names: a LOD parent's far level, blocks or leaves. */
function tileKind(uri) {
  const name = decodeURIComponent(uri.split("?")[0].split("/").pop());
  if (name.endsWith("_finest.glb")) return "leaves";
  if (name.endsWith("_coarsest.glb")) return "blocks";
  if (name.endsWith(".json")) return "external tileset";
  return "far level";
}

/** The content URI relative to the page's tileset, as tileset.json names it. */
function relative(url) {
  const base = new URL(config.asset, location.href);
  const path = new URL(url, location.href).pathname;
  const folder = base.pathname.slice(0, base.pathname.lastIndexOf("/") + 1);
  return decodeURIComponent(path.startsWith(folder) ? path.slice(folder.length) : path);
}

const describe = (tile) => {
  const uri = relative(tile.content.url);
  return { uri, kind: tileKind(uri), geometricError: tile.geometricError };
};

let hovered = "";

function showReadout() {
  const counts = {};
  for (const { kind } of state.tiles) counts[kind] = (counts[kind] ?? 0) + 1;
  const kinds = Object.entries(counts).map(([kind, n]) => `${n} ${kind}`).join(", ");
  const lines = [`tiles selected: ${state.tiles.length}${kinds ? ` (${kinds})` : ""}`];
  lines.push(`maximumScreenSpaceError ${config.sse} (--sse)`);
  if (hovered) lines.push(`under the pointer: ${hovered}`);
  if (state.failed.length) lines.push(`failed to load: ${state.failed.map((f) => f.uri).join(", ")}`);
  readout.textContent = lines.join("\n");
}

/** `value` as JSON can hold it: an INT64 property (a BigInt) as a number, or as text beyond
 * 2^53. */
function plain(value) {
  if (typeof value !== "bigint") return value;
  return Number.isSafeInteger(Number(value)) ? Number(value) : String(value);
}

/** The picked object at CSS pixel (x, y) of the view: a building's feature, a tile, or null. */
function pickAt(x, y) {
  const rect = widget.canvas.getBoundingClientRect();
  const picked = widget.scene.pick(new Cesium.Cartesian2(x - rect.left, y - rect.top));
  if (!picked) return null;
  const content = picked.content ?? picked;
  const tile = content.tile ? describe(content.tile) : null;
  if (!(picked instanceof Cesium.Cesium3DTileFeature)) return tile;
  const properties = {};
  for (const name of picked.getPropertyIds()) properties[name] = plain(picked.getProperty(name));
  return { ...tile, id: properties.id ?? null, properties, feature: picked };
}

/** A STRING property holding a nested value as JSON (the writer's way), as that value. */
function nested(value) {
  if (typeof value !== "string" || !/^[[{]/.test(value)) return value;
  try {
    return JSON.parse(value);
  } catch {
    return value;
  }
}

const tileLine = (tile) => `${tile.uri} (${tile.kind}, geometricError ${tile.geometricError.toPrecision(4)})`;

/** Show the picked building `picked` (null: nothing) in the panel and tint it. */
function select(picked) {
  if (highlighted) highlighted.color = Cesium.Color.WHITE;
  highlighted = picked?.feature ?? null;
  if (highlighted) highlighted.color = Cesium.Color.fromCssColorString(HIGHLIGHT);
  state.selected = picked?.id ?? null;
  state.picked = picked ? { ...picked, feature: undefined } : null;
  inspect.hidden = state.selected === null;
  inspect.replaceChildren();
  widget.scene.requestRender();
  if (state.selected === null) return;
  const heading = document.createElement("h2");
  heading.textContent = state.selected;
  const table = document.createElement("table");
  const { id, ...others } = picked.properties;
  const attributes = Object.fromEntries(Object.entries(others).map(([k, v]) => [k, nested(v)]));
  addAttributes(table, { ...attributes, tile: tileLine(picked) });
  const close = document.createElement("button");
  Object.assign(close, { type: "button", className: "close", textContent: "×", title: "Deselect" });
  inspect.append(close, heading, table);
}

function watchPointer(view) {
  let pressed = null;
  let pending = null;
  view.addEventListener("pointerdown", (event) => { pressed = [event.clientX, event.clientY]; });
  view.addEventListener("click", (event) => {
    if (pressed === null) return;
    if (Math.hypot(event.clientX - pressed[0], event.clientY - pressed[1]) > CLICK_SLOP_PX) return;
    select(pickAt(event.clientX, event.clientY));
    state.clicks += 1;
  });
  view.addEventListener("pointermove", (event) => {
    if (pending === null) requestAnimationFrame(() => {
      const tile = pickAt(...pending);
      hovered = tile ? `${tile.id ? `${tile.id} in ` : ""}${tileLine(tile)}` : "";
      pending = null;
      showReadout();
    });
    pending = [event.clientX, event.clientY];
  });
  inspect.addEventListener("click", (event) => {
    if (event.target.closest("button.close")) select(null);
  });
}

/** Track the tiles each frame selects; resolve `settle` promises once two frames in a row after
 * the move have every tile their view needs loaded (CesiumJS's tilesLoaded): the first frame
 * after a move only starts the requests of its view, and may select nothing yet. */
let frame = new Set();
let waiting = [];
let loadedFrames = 0;
function watchFrames() {
  const scene = widget.scene;
  scene.preUpdate.addEventListener(() => { frame = new Set(); });
  tileset.tileVisible.addEventListener((tile) => frame.add(tile));
  tileset.tileFailed.addEventListener((failure) => {
    state.failed.push({ uri: relative(failure.url), message: failure.message });
    showReadout();
  });
  scene.postRender.addEventListener(() => {
    state.tiles = [...frame].filter((tile) => tile.content?.url).map(describe);
    showReadout();
    loadedFrames = tileset.tilesLoaded ? loadedFrames + 1 : 0;
    if (loadedFrames >= 2) {
      state.settled = true;
      waiting.forEach((done) => done());
      waiting = [];
    } else if (waiting.length) scene.requestRender(); // until the tiles are in
  });
}

/** Light the scene from above the camera, each frame: down-and-forward, half-way between the
 * view direction and straight down, so that roofs face it nearly straight on and the walls
 * facing the camera are half lit. CesiumJS's default light, the sun at the clock's time, leaves
 * a city dark at night and at dusk. */
function lightFromAboveTheCamera(scene) {
  const light = new Cesium.DirectionalLight({
    direction: new Cesium.Cartesian3(0, 0, -1),
    intensity: LIGHT_INTENSITY,
  });
  const down = new Cesium.Cartesian3();
  scene.light = light;
  scene.preRender.addEventListener(() => {
    const camera = scene.camera;
    Cesium.Ellipsoid.WGS84.geodeticSurfaceNormal(camera.positionWC, down);
    Cesium.Cartesian3.negate(down, down);
    const forward = Cesium.Cartesian3.add(camera.directionWC, down, light.direction);
    // looking straight up, the two cancel: light from straight above
    if (Cesium.Cartesian3.magnitude(forward) < 1e-6) Cesium.Cartesian3.clone(down, forward);
    Cesium.Cartesian3.normalize(forward, light.direction);
  });
}

/** Resolves once the view is settled after a change. */
function settle() {
  state.settled = false;
  loadedFrames = 0;
  const done = new Promise((resolve) => waiting.push(resolve));
  widget.scene.requestRender();
  return done;
}

/** Look at `target` (ECEF, default the tileset's centre) from `range` metres (default 2.5×
 * its radius), `heading` and `pitch` degrees. */
function lookAt({ target = null, range = null, heading = 0, pitch = PITCH_DEG } = {}) {
  const sphere = tileset.boundingSphere;
  const centre = target ? new Cesium.Cartesian3(...target) : sphere.center;
  const offset = new Cesium.HeadingPitchRange(
    Cesium.Math.toRadians(heading), Cesium.Math.toRadians(pitch), range ?? 2.5 * sphere.radius);
  widget.camera.lookAt(centre, offset);
  widget.camera.lookAtTransform(Cesium.Matrix4.IDENTITY); // free the camera for the user
}

/** The first view from the page's URL (?target=X,Y,Z&range=&heading=&pitch=), if it names one. */
function urlView() {
  const query = new URLSearchParams(location.search);
  if (!query.has("target") && !query.has("range")) return {};
  const number = (name) => (query.has(name) ? Number(query.get(name)) : undefined);
  const target = query.get("target")?.split(",").map(Number) ?? null;
  return { target, range: number("range"), heading: number("heading"), pitch: number("pitch") };
}

/** Import CesiumJS from the page's import map, naming its URL if it fails. */
async function importCesium() {
  window.CESIUM_BASE_URL = new URL(config.library.base, location.href).href;
  const css = document.createElement("link");
  Object.assign(css, { rel: "stylesheet", href: `${window.CESIUM_BASE_URL}Widgets/widgets.css` });
  document.head.append(css);
  try {
    return await import("cesium");
  } catch (error) {
    console.error(error);
    const { package: name, version } = config.library;
    throw new Error(`Could not load the viewer library\n${window.CESIUM_BASE_URL}\n\n` +
      `Re-run lodconvert with --viewer-lib DIR, DIR a local copy of the npm package ` +
      `${name}@${version} (npm install ${name}@${version}), or serve it beside the page:\n` +
      "lodconvert view tileset.json --serve --viewer-lib DIR");
  }
}

async function start() {
  if (location.protocol === "file:") {
    throw new Error("Browsers do not let a page opened from a file load the tileset: serve " +
      "this folder (lodconvert view tileset.json --serve) and open the URL it prints.");
  }
  const started = performance.now();
  readout.textContent = "loading CesiumJS …";
  Cesium = await importCesium();
  const view = document.getElementById("view");
  widget = new Cesium.CesiumWidget(view, {
    baseLayer: false,
    terrainProvider: new Cesium.EllipsoidTerrainProvider(),
    skyBox: false,
    skyAtmosphere: false,
    requestRenderMode: true,
    maximumRenderTimeChange: Infinity,
  });
  widget.scene.globe.baseColor = Cesium.Color.fromCssColorString("#4a4f58");
  lightFromAboveTheCamera(widget.scene);
  readout.textContent = `loading ${config.asset} …`;
  tileset = await Cesium.Cesium3DTileset.fromUrl(config.asset, {
    maximumScreenSpaceError: config.sse,
  }).catch((error) => {
    throw new Error(`Could not load the tileset\n${new URL(config.asset, location.href)}\n${error}`);
  });
  if (config.pointCloudShading) {
    tileset.pointCloudShading = new Cesium.PointCloudShading(config.pointCloudShading);
  }
  widget.scene.primitives.add(tileset);
  watchFrames();
  watchPointer(view);
  state.screenPoint = (point) => {
    const at = widget.scene.cartesianToCanvasCoordinates(new Cesium.Cartesian3(...point));
    if (!at) return null;
    const rect = widget.canvas.getBoundingClientRect();
    return { x: rect.left + at.x, y: rect.top + at.y };
  };
  state.setCamera = async (camera) => {
    lookAt(camera);
    await settle();
  };
  await state.setCamera(urlView());
  state.loadMs = performance.now() - started;
  state.ready = true;
}

start().catch((error) => {
  state.error = String(error?.message ?? error);
  readout.textContent = "not shown: see the message over the view";
  alertBox(state.error);
  console.error(error);
});
