// lodconvert viewer page, common part: the configuration written by lodconvert, the readout of
// each object's active level and distance, the distance slider, and window.lodconvertViewer
// (state for tests and curious users, and setDistance). The format part after it (gltf.js or
// x3d.js) defines a backend { load(host), setDistance(d) } and calls start(backend); it reports
// levels and distances through update().

const config = JSON.parse(document.getElementById("lodconvert-config").textContent);
const first = config.objects[0];
const readout = document.getElementById("readout");
const slider = document.getElementById("distance");
const status = document.getElementById("status");
const MAX_LISTED = 8;

// The slider spans half the diagonal to twice the last cutoff, logarithmically.
const nearest = first.alpha / 2;
const farthest = 2 * Math.max(first.alpha, ...first.cutoffs);
const sliderDistance = (value) => nearest * (farthest / nearest) ** (value / 1000);
const sliderValue = (distance) => (1000 * Math.log(distance / nearest)) / Math.log(farthest / nearest);

const state = {
  ready: false,
  error: null,
  loadMs: null,
  objects: config.objects.map((o) => ({ id: o.id, level: null, levelIndex: null, distance: null })),
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
      await backend.setDistance(distance);
      slider.value = String(sliderValue(distance));
    };
    slider.addEventListener("input", () => backend.setDistance(sliderDistance(Number(slider.value))));
    await state.setDistance(1.25 * first.alpha); // the whole object in view, finest level
    state.loadMs = performance.now() - started;
    state.ready = true;
  } catch (error) {
    fail(error);
  }
}
