// lodconvert viewer page, common part: the configuration written by lodconvert, the readout of
// each object's active level and distance, the distance slider, and window.lodconvertViewer
// (state for tests and curious users, and setDistance). The format part after it (gltf.js or
// x3d.js) defines a backend { load(host), setDistance(d) } and calls start(backend); it reports
// levels and distances through update().

const config = JSON.parse(document.getElementById("lodconvert-config").textContent);
const readout = document.getElementById("readout");
const slider = document.getElementById("distance");
const status = document.getElementById("status");
const MAX_LISTED = 8;

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
  setDistance: null,
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
    await backend.load(document.getElementById("view"));
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
