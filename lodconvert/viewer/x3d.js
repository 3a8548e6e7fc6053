// X3D part: X_ITE loads the file and switches its LOD nodes itself (at the ranges lodconvert
// wrote, points sized by PointProperties); the page adds a viewpoint it can move, and reads the
// levels from level_changed and the viewer position from a ProximitySensor. The library is
// imported in load(), so that a wrong library URL is reported on the page.

const levels = config.objects.map(() => null);
const distances = config.objects.map(() => null);
let X3D, viewpoint;

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
    viewpoint.centerOfRotation = vector(first.center);
    const sensor = scene.createNode("ProximitySensor");
    sensor.center = vector(first.center);
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
  async setDistance(distance) {
    viewpoint.position = vector([first.center[0], first.center[1], first.center[2] + distance]);
    viewpoint.set_bind = true;
    await nextFrame();
  },
};

start(backend);
