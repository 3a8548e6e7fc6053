// X3D part: X_ITE loads the file and switches its LOD nodes itself (at the ranges lodconvert
// wrote, points sized by PointProperties); the page adds a viewpoint it can move, and reads the
// levels from level_changed and the viewer position and orientation from a ProximitySensor.
// A click is picked by X_ITE itself, with the browser methods its pointing-device sensors use
// (getPointerFromEvent, touch(x, y), then getHit(): the Shape drawn at that pixel; they are not
// part of its typed API), and the page maps the Shape to the object whose LOD holds it; objects
// that USE another's LOD (instances) share its Shapes, and a click on one selects the first.
// The library is imported in load(), so that a wrong library URL is reported on the page.

/**
 * Frames that a move waits at most for every LOD to reach its level: with forceTransitions
 * (as lodconvert writes them) X_ITE steps one level a frame, so a few frames suffice.
 */
const SETTLE_FRAMES = 120;
const levels = config.objects.map(() => null);
const distances = config.objects.map(() => null);
const objectOfShape = new Map(); // Shape (X_ITE's node, not its SFNode) → first object's index
let X3D, browser, canvas, viewpoint;
const eye = { position: focus, orientation: null }; // the viewer's, from the sensor
let target = 0;

const vector = (values) => new X3D.SFVec3f(...values);

function report(index) {
  update(index, levels[index], distances[index]);
}

/** Record in objectOfShape that the Shapes under `node` are drawn by object `index`. */
function collectShapes(node, index) {
  if (node.getNodeTypeName() === "Shape") {
    if (!objectOfShape.has(node.getValue())) objectOfShape.set(node.getValue(), index);
    return;
  }
  const grouping = node.getFieldDefinitions().some((field) => field.name === "children");
  for (const child of grouping ? node.children : []) {
    if (child) collectShapes(child, index);
  }
}

function viewerMoved(position) {
  eye.position = position;
  config.objects.forEach((object, i) => {
    distances[i] = Math.hypot(...object.center.map((c, k) => position[k] - c));
    report(i);
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
    sensor.size = vector([40 * farthest, 40 * farthest, 40 * farthest]);
    eye.orientation = new X3D.SFRotation();
    sensor.addFieldCallback("lodconvert", "position_changed", (p) => viewerMoved([p.x, p.y, p.z]));
    sensor.addFieldCallback("lodconvert", "orientation_changed", (r) => { eye.orientation = r; });
    for (const node of [navigation, viewpoint, sensor]) scene.rootNodes.push(node);
    navigation.set_bind = true;
    config.objects.forEach((object, i) => {
      const lod = scene.getNamedNode(object.lod);
      collectShapes(lod, i);
      levels[i] = lod.level_changed;
      lod.addFieldCallback("lodconvert", "level_changed", (level) => {
        levels[i] = level;
        report(i);
      });
    });
  },
  /** Resolves once every LOD shows its level at the new place, and the sensor reported it. */
  async setDistance(distance) {
    const move = ++target;
    const position = [focus[0], focus[1], focus[2] + distance];
    viewpoint.position = vector(position);
    viewpoint.set_bind = true;
    const expected = config.objects.map((object) => {
      const d = Math.hypot(...object.center.map((c, k) => position[k] - c));
      return { level: levelAt(object, d), distance: d };
    });
    const arrived = () => expected.every((e, i) =>
      levels[i] === e.level && Math.abs(distances[i] - e.distance) <= 1e-4 * e.distance);
    for (let frame = 0; frame < SETTLE_FRAMES && move === target; frame++) {
      await nextFrame();
      if (arrived()) break;
    }
  },
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
