// glTF part: three.js draws each MSFT_lod chain as a THREE.LOD whose levels switch at the chain's
// cutoffs (extras.lodconvert), points sized as lodconvert sizes them. The library is imported in
// load(), so that a wrong library URL is reported on the page.

const halfFov = (config.view.fov_y_deg * Math.PI) / 360;
const referenceFocal = config.view.height_px / (2 * Math.tan(halfFov));
const lods = [];
let THREE, renderer, scene, camera, controls, origin;

/**
 * Points `size.px` pixels wide at `size.distance` in the reference view, shrinking with 1/r:
 * three.js draws an attenuated point size·(H/2)/r pixels in a viewport H pixels high, which is
 * size.px·size.distance/r scaled from the reference focal length to this camera's.
 */
function pointsMaterial(material, size) {
  const sized = material.clone();
  sized.size = (size.px * size.distance) / (referenceFocal * Math.tan(halfFov));
  sized.sizeAttenuation = true;
  return sized;
}

function render() {
  renderer.render(scene, camera); // also picks each LOD's level
  lods.forEach((lod, i) => update(i, lod.getCurrentLevel(), camera.position.distanceTo(lod.position)));
}

function resize(host) {
  camera.aspect = host.clientWidth / host.clientHeight;
  camera.updateProjectionMatrix();
  renderer.setSize(host.clientWidth, host.clientHeight);
  render();
}

async function buildLod(gltf, object) {
  const lod = new THREE.LOD();
  lod.position.set(...object.center).sub(origin);
  for (const [k, index] of [object.node, ...object.ids].entries()) {
    const level = await gltf.parser.getDependency("node", index);
    level.position.set(...object.local_center).negate(); // geometry is relative to the origin
    level.traverse((part) => {
      if (part.isPoints && object.points[k]) part.material = pointsMaterial(part.material, object.points[k]);
    });
    lod.addLevel(level, k === 0 ? 0 : object.cutoffs[k - 1]);
  }
  if (object.culled) lod.addLevel(new THREE.Object3D(), object.cutoffs.at(-1));
  return lod;
}

const backend = {
  async load(host) {
    let GLTFLoader, OrbitControls;
    [THREE, { GLTFLoader }, { OrbitControls }] = await Promise.all([
      import("three"),
      import("three/addons/loaders/GLTFLoader.js"),
      import("three/addons/controls/OrbitControls.js"),
    ]);
    origin = new THREE.Vector3(...first.center); // the page's origin, so float32 keeps precision
    renderer = new THREE.WebGLRenderer({ antialias: true });
    renderer.setPixelRatio(window.devicePixelRatio);
    host.appendChild(renderer.domElement);
    scene = new THREE.Scene();
    scene.background = new THREE.Color(0x202226);
    camera = new THREE.PerspectiveCamera(config.view.fov_y_deg, 1, first.alpha / 100, 10 * farthest);
    camera.add(new THREE.DirectionalLight(0xffffff, 1.5));
    scene.add(camera, new THREE.HemisphereLight(0xffffff, 0x444444, 2));
    const gltf = await new GLTFLoader().loadAsync(config.asset);
    for (const object of config.objects) {
      const lod = await buildLod(gltf, object);
      scene.add(lod);
      lods.push(lod);
    }
    controls = new OrbitControls(camera, renderer.domElement);
    controls.addEventListener("change", render);
    window.addEventListener("resize", () => resize(host));
    camera.position.set(0, 0, 1);
    resize(host);
  },
  async setDistance(distance) {
    const direction = camera.position.clone().sub(controls.target).normalize();
    camera.position.copy(controls.target).addScaledVector(direction, distance);
    controls.update();
    render();
    await nextFrame();
  },
};

start(backend);
