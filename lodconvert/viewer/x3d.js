// X3D part: X_ITE loads the file and switches its LOD nodes itself (at the ranges lodconvert
// wrote, points sized by PointProperties); the page adds a viewpoint it can move, and reads the
// levels from level_changed and the viewer position from a ProximitySensor. The library is
// imported in load(), so that a wrong library URL is reported on the page.

/**
 * Frames that a move waits at most for every LOD to reach its level: with forceTransitions
 * (as lodconvert writes them) X_ITE steps one level a frame, so a few frames suffice.
 */
const SETTLE_FRAMES = 120;
const levels = config.objects.map(() => null);
const distances = config.objects.map(() => null);
let X3D, viewpoint;
let target = 0;

const vector = (values) => new X3D.SFVec3f(...values);

function report(index) {
  update(index, levels[index], distances[index]);
}

function viewerMoved(position) {
  config.objects.forEach((object, i) => {
    distances[i] = Math.hypot(...object.center.map((c, k) => position[k] - c));
    report(i);
  });
}

const backend = {
  async load(host) {
    ({ default: X3D } = await import("x_ite"));
    const canvas = document.createElement("x3d-canvas");
    canvas.setAttribute("splashScreen", "false");
    canvas.setAttribute("notifications", "false");
    host.appendChild(canvas);
    const browser = X3D.getBrowser(canvas);
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
    sensor.addFieldCallback("lodconvert", "position_changed", (p) => viewerMoved([p.x, p.y, p.z]));
    for (const node of [navigation, viewpoint, sensor]) scene.rootNodes.push(node);
    navigation.set_bind = true;
    config.objects.forEach((object, i) => {
      const lod = scene.getNamedNode(object.lod);
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
};

start(backend);
