// X3D part: X_ITE loads the file and switches its LOD nodes itself (at the ranges lodconvert
// wrote, points sized by PointProperties; a LOD parent's LOD holds its members' nodes, so the
// LODs nest); the page adds a viewpoint it can move, and reads the levels of objects and cells
// from level_changed (with prism switching, an object's from its Switches' whichChoice) and the
// viewer position and orientation from a ProximitySensor. The LOD scale sets the LODs' range
// and grows the prism sensors' boxes by the scaled cutoffs.
// A click is picked by X_ITE itself, with the browser methods its pointing-device sensors use
// (getPointerFromEvent, touch(x, y), then getHit(): the Shape drawn at that pixel; they are not
// part of its typed API), and the page maps the Shape to the object whose LOD holds it; objects
// that USE another's LOD (instances) share its Shapes, and a click on one selects the first;
// the clicked object's Materials glow (emissiveColor) until another or nothing is clicked.
// The library is imported in load(), so that a wrong library URL is reported on the page.

/**
 * Frames that a move waits at most for every LOD to reach its level: with forceTransitions
 * (as lodconvert writes them) X_ITE steps one level a frame, so a few frames suffice.
 */
const SETTLE_FRAMES = 120;
const levels = config.objects.map(() => null);
const distances = config.objects.map(() => null);
const cellLevels = cells.map(() => null);
const cellDistances = cells.map(() => null);
const scalings = []; // per LOD or prism sensor, (scale) => what it needs for a new LOD scale
/** Per object, (viewer position) => the level it should show there. */
const levelsAt = config.objects.map((object) => (position) => {
  return levelAt(object, distanceBetween(object.center, position));
});
const objectOfShape = new Map(); // Shape (X_ITE's node, not its SFNode) → first object's index
const shapesOf = config.objects.map(() => []); // per object, the Shapes (SFNodes) of its levels
let X3D, browser, canvas, viewpoint;
const eye = { position: focus, orientation: null }; // the viewer's, from the sensor
let target = 0;

const vector = (values) => new X3D.SFVec3f(...values);

function report(index) {
  update(index, levels[index], distances[index]);
}

function reportCell(index) {
  updateCell(index, cellLevels[index], cellDistances[index]);
}

let watchers = 0;

/** Call `changed(value)` with the value of `node`'s field `name` now and whenever it changes. */
function watch(node, name, changed) {
  node.addFieldCallback(`lodconvert ${++watchers}`, name, changed);
  changed(node[name]);
}

/**
 * Follow the level of the LOD node `lod` (of an object or cell `entry`) into `into[index]`,
 * reporting it by `reported(index)`; a LOD scale sets its range to the scaled cutoffs.
 */
function followLod(lod, entry, into, index, reported) {
  watch(lod, "level_changed", (level) => {
    into[index] = level;
    reported(index);
  });
  scalings.push((scale) => { lod.range = new X3D.MFFloat(...entry.cutoffs.map((c) => c * scale)); });
}

/**
 * The nodes of prism-switched `object` in `role` (its "Switch"es or its sensors, "Prism"), one
 * per cutoff, nearest first: lodconvert's writer names them after the object's Transform.
 */
const prismNodes = (scene, object, role) =>
  object.cutoffs.map((_, k) => scene.getNamedNode(`${object.transform}_${role}${k}`));

/**
 * Follow the level that object `index`, prism-switched, shows: that of its first Switch at its
 * near choice (0), else its coarsest (or nothing, culled); an object of one level has no
 * Switch, nothing to follow, and shows that level.
 */
function followSwitches(scene, object, index) {
  const switches = prismNodes(scene, object, "Switch");
  const read = () => {
    const near = switches.findIndex((node) => node.whichChoice === 0);
    levels[index] = near < 0 ? switches.length : near;
    report(index);
  };
  for (const node of switches) watch(node, "whichChoice", read);
  if (switches.length === 0) read(); // a single level has no Switch: it always shows
}

/**
 * Object `index`, prism-switched, should show the level of the first of its sensors' boxes that
 * holds the viewer (its coarsest outside them). The boxes are the finest level's box grown by
 * each cutoff on every side, so a LOD scale grows them by the scaled cutoff.
 */
function followBoxes(scene, object, index) {
  const sensors = prismNodes(scene, object, "Prism");
  sensors.forEach((sensor, k) => {
    const size = [sensor.size.x, sensor.size.y, sensor.size.z];
    const grown = (scale) => 2 * (scale - 1) * object.cutoffs[k];
    scalings.push((scale) => { sensor.size = vector(size.map((v) => v + grown(scale))); });
  });
  const holds = (sensor, local) => ["x", "y", "z"].every((axis, k) => {
    return Math.abs(local[k] - sensor.center[axis]) < sensor.size[axis] / 2;
  });
  levelsAt[index] = (position) => { // in the object's Transform (its source axes)
    const local = turned(position.map((v, k) => v - object.center[k]), true)
      .map((v, k) => v + object.local_center[k]);
    const inside = sensors.findIndex((sensor) => holds(sensor, local));
    return inside < 0 ? sensors.length : inside;
  };
}

/**
 * Record in objectOfShape that the Shapes under `node` are drawn by object `index`, and add
 * them to its shapesOf.
 */
function collectShapes(node, index) {
  if (node.getNodeTypeName() === "Shape") {
    if (!objectOfShape.has(node.getValue())) objectOfShape.set(node.getValue(), index);
    shapesOf[index].push(node);
    return;
  }
  const grouping = node.getFieldDefinitions().some((field) => field.name === "children");
  for (const child of grouping ? node.children : []) {
    if (child) collectShapes(child, index);
  }
}

/** The emissive colour that highlights the clicked object. */
const HIGHLIGHT = [0.6, 0.36, 0];
/** [Material, its emissiveColor before] of each Material the highlight tints. */
let highlighted = [];

/**
 * Tint the Materials of object `index`'s Shapes (null: none) by HIGHLIGHT, restoring those
 * tinted before. Each level has Appearances of its own (instances share them, and so the
 * highlight); a PointSet draws its own colours, unlit, and does not show it.
 */
function highlightObject(index) {
  for (const [material, emissive] of highlighted) material.emissiveColor = emissive;
  const materials = new Map(); // node → SFNode, each once
  for (const shape of index === null ? [] : shapesOf[index]) {
    const material = shape.appearance?.material;
    if (material) materials.set(material.getValue(), material);
  }
  highlighted = [...materials.values()].map((m) => [m, m.emissiveColor.copy()]);
  for (const [material] of highlighted) material.emissiveColor = new X3D.SFColor(...HIGHLIGHT);
}

function viewerMoved(position) {
  eye.position = position;
  config.objects.forEach((object, i) => {
    distances[i] = distanceBetween(object.center, position);
    report(i);
  });
  cells.forEach((cell, i) => {
    cellDistances[i] = distanceBetween(cell.center, position);
    reportCell(i);
  });
}

/**
 * Whether, with the viewer at `position`, every object and cell whose own LOD (or Switches) is
 * drawn shows the level it should there, and every distance arrived.
 */
function arrivedAt(position) {
  const near = (seen, expected) => Math.abs(seen - expected) <= 1e-4 * expected;
  const expectedCells = cells.map((cell) => levelAt(cell, distanceBetween(cell.center, position)));
  const drawn = (holder) => holder === null || closedCell(holder, (i) => expectedCells[i]) === null;
  const objectsArrived = config.objects.every((object, i) => {
    const distance = distanceBetween(object.center, position);
    const own = !drawn(object.cell) || levels[i] === levelsAt[i](position);
    return own && near(distances[i], distance);
  });
  return objectsArrived && cells.every((cell, i) => {
    const own = !drawn(cell.parent) || cellLevels[i] === expectedCells[i];
    return own && near(cellDistances[i], distanceBetween(cell.center, position));
  });
}

const backend = {
  async load(host) {
    ({ default: X3D } = await import("x_ite"));
    canvas = document.createElement("x3d-canvas");
    canvas.setAttribute("splashScreen", "false");
    canvas.setAttribute("notifications", "false");
    host.appendChild(canvas);
    browser = X3D.getBrowser(canvas);
    await browser.loadURL(new X3D.MFString(config.asset));
    const scene = browser.currentScene;
    scene.addComponent(browser.getComponent("EnvironmentalSensor", 1)); // ProximitySensor
    const navigation = scene.createNode("NavigationInfo");
    navigation.type = new X3D.MFString("EXAMINE", "ANY");
    navigation.transitionType = new X3D.MFString("TELEPORT");
    viewpoint = scene.createNode("Viewpoint");
    viewpoint.description = "lodconvert viewer";
    viewpoint.fieldOfView = (config.view.fov_y_deg * Math.PI) / 180;
    viewpoint.centerOfRotation = vector(focus);
    const sensor = scene.createNode("ProximitySensor");
    sensor.center = vector(focus);
    const reaching = () => { sensor.size = vector([40 * farthest, 40 * farthest, 40 * farthest]); };
    reaching();
    scalings.push(reaching);
    eye.orientation = new X3D.SFRotation();
    sensor.addFieldCallback("lodconvert", "position_changed", (p) => viewerMoved([p.x, p.y, p.z]));
    sensor.addFieldCallback("lodconvert", "orientation_changed", (r) => { eye.orientation = r; });
    for (const node of [navigation, viewpoint, sensor]) scene.rootNodes.push(node);
    navigation.set_bind = true;
    const prism = scene.getMetaData("switching")?.includes("prism"); // as the file declares
    config.objects.forEach((object, i) => {
      const lod = scene.getNamedNode(object.lod);
      collectShapes(lod, i);
      if (!prism) followLod(lod, object, levels, i, report);
      else {
        followSwitches(scene, object, i);
        followBoxes(scene, object, i);
      }
    });
    cells.forEach((cell, i) => {
      followLod(scene.getNamedNode(cell.lod), cell, cellLevels, i, reportCell);
    });
  },
  /** Resolves once every LOD drawn shows its level at the new place, and the sensor said so. */
  async setDistance(distance) {
    const move = ++target;
    const position = focus.map((v, k) => v + distance * viewDirection[k]);
    viewpoint.position = vector(position);
    const pitch = Math.atan2(viewDirection[1], viewDirection[2]); // looking down at the focus
    viewpoint.orientation = new X3D.SFRotation(1, 0, 0, -pitch);
    viewpoint.set_bind = true;
    for (let frame = 0; frame < SETTLE_FRAMES && move === target; frame++) {
      await nextFrame();
      if (arrivedAt(position)) break;
    }
  },
  /** Switch at `scale` times every cutoff (drawn by the next move), seeing to the slider's end. */
  setLodScale(scale) {
    for (const scaling of scalings) scaling(scale);
  },
  highlight: highlightObject,
  /** Index of the object drawing the Shape under the pointer of `event`, or null. */
  pick(event) {
    const { x, y } = browser.getPointerFromEvent(event);
    if (!browser.touch(x, y)) return null;
    return objectOfShape.get(browser.getHit().shapeNode) ?? null;
  },
  /**
   * Where the world point `point` shows on the page (CSS pixels); null behind the viewer. As
   * X3D specifies, the field of view spans the shorter side of the canvas.
   */
  screenPoint(point) {
    const relative = vector(point.map((v, k) => v - eye.position[k]));
    const seen = eye.orientation.inverse().multVec(relative); // the viewer looks along -z
    if (seen.z >= 0) return null;
    const rect = canvas.getBoundingClientRect();
    const focal = Math.min(rect.width, rect.height) / 2 / Math.tan(viewpoint.fieldOfView / 2);
    return {
      x: rect.left + rect.width / 2 + (focal * seen.x) / -seen.z,
      y: rect.top + rect.height / 2 - (focal * seen.y) / -seen.z,
    };
  },
};

start(backend);
