// glTF part: three.js draws each MSFT_lod chain as a THREE.LOD whose levels switch at the chain's
// cutoffs (extras.lodconvert), points sized as lodconvert sizes them and lit like the mesh; a
// ray through the clicked pixel picks the nearest level shown, and so its object. The library
// is imported in load(), so that a wrong library URL is reported on the page.

const halfFov = (config.view.fov_y_deg * Math.PI) / 360;
const referenceFocal = config.view.height_px / (2 * Math.tan(halfFov));
const lods = [];
const pointScale = { value: 1 }; // half the drawing buffer's height, set by resize()
let THREE, renderer, scene, camera, controls, origin, raycaster;

/**
 * The material of a point level's `material` (which GLTFLoader made unlit): lit like the mesh
 * level instead (the points carry normals; the writer's materials are metalness 0, roughness 1),
 * so that switching from mesh to points keeps the shading. The mesh is double-sided, so the
 * side facing the viewer is lit whichever way its normals point; a point has no sides, so its
 * normal is turned toward the viewer likewise. Its points are `size.px` pixels wide at
 * `size.distance` in the reference view, shrinking with 1/r: as three.js attenuates points,
 * they are pointSize·(H/2)/r pixels in a drawing buffer H pixels high, which is
 * size.px·size.distance/r scaled from the reference focal length to this camera's.
 */
function pointsMaterial(material, size) {
  const lit = new THREE.MeshStandardMaterial({ metalness: 0, roughness: 1 });
  THREE.Material.prototype.copy.call(lit, material); // vertex colours, transparency, ...
  lit.color.copy(material.color);
  const pointSize = { value: (size.px * size.distance) / (referenceFocal * Math.tan(halfFov)) };
  lit.onBeforeCompile = (shader) => {
    Object.assign(shader.uniforms, { pointSize, pointScale });
    const vertex = shader.vertexShader.replace(
      "#include <project_vertex>",
      "#include <project_vertex>\n\tgl_PointSize = pointSize * pointScale / -mvPosition.z;",
    );
    shader.vertexShader = `uniform float pointSize;\nuniform float pointScale;\n${vertex}`;
    shader.fragmentShader = shader.fragmentShader.replace(
      "#include <normal_fragment_begin>",
      "#include <normal_fragment_begin>\n\tnormal = faceforward(normal, -vViewPosition, normal);",
    );
  };
  return lit;
}

/**
 * Let rays hit the points of `points` within their drawn radius: they are drawn
 * size.px·size.distance / referenceFocal world units wide (see pointsMaterial), at every
 * distance.
 */
function pickLikeDrawn(points, size) {
  const radius = (size.px * size.distance) / referenceFocal / 2;
  points.raycast = (ray, hits) => {
    ray.params.Points.threshold = radius;
    THREE.Points.prototype.raycast.call(points, ray, hits);
  };
}

/** Whether `object` is drawn: it and all its ancestors are visible (LODs hide levels). */
function drawn(object) {
  for (let node = object; node; node = node.parent) if (!node.visible) return false;
  return true;
}

/** The CSS pixel position of `event` as normalised device coordinates of the canvas. */
function deviceCoordinates(event) {
  const rect = renderer.domElement.getBoundingClientRect();
  const x = ((event.clientX - rect.left) / rect.width) * 2 - 1;
  return new THREE.Vector2(x, 1 - ((event.clientY - rect.top) / rect.height) * 2);
}

function render() {
  renderer.render(scene, camera); // also picks each LOD's level
  lods.forEach((lod, i) => update(i, lod.getCurrentLevel(), camera.position.distanceTo(lod.position)));
}

function resize(host) {
  camera.aspect = host.clientWidth / host.clientHeight;
  camera.updateProjectionMatrix();
  renderer.setSize(host.clientWidth, host.clientHeight);
  pointScale.value = renderer.getDrawingBufferSize(new THREE.Vector2()).y / 2;
  render();
}

async function buildLod(gltf, object) {
  const lod = new THREE.LOD();
  lod.position.set(...object.center).sub(origin);
  for (const [k, index] of [object.node, ...object.ids].entries()) {
    const level = await gltf.parser.getDependency("node", index);
    level.position.set(...object.local_center).negate(); // geometry is relative to the origin
    level.traverse((part) => {
      if (part.isPoints && object.points[k]) {
        part.material = pointsMaterial(part.material, object.points[k]);
        pickLikeDrawn(part, object.points[k]);
      }
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
    origin = new THREE.Vector3(...focus); // the page's origin, so float32 keeps precision
    renderer = new THREE.WebGLRenderer({ antialias: true });
    renderer.setPixelRatio(window.devicePixelRatio);
    host.appendChild(renderer.domElement);
    scene = new THREE.Scene();
    scene.background = new THREE.Color(0x202226);
    camera = new THREE.PerspectiveCamera(config.view.fov_y_deg, 1, nearest / 50, 10 * farthest);
    camera.add(new THREE.DirectionalLight(0xffffff, 1.5));
    scene.add(camera, new THREE.HemisphereLight(0xffffff, 0x444444, 2));
    const gltf = await new GLTFLoader().loadAsync(config.asset);
    for (const object of config.objects) {
      const lod = await buildLod(gltf, object);
      scene.add(lod);
      lods.push(lod);
    }
    raycaster = new THREE.Raycaster();
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
  /** Index of the object of the nearest drawn level under the pointer of `event`, or null. */
  pick(event) {
    raycaster.setFromCamera(deviceCoordinates(event), camera);
    const hit = raycaster.intersectObjects(lods, true).find((h) => drawn(h.object));
    let node = hit?.object;
    while (node && !node.isLOD) node = node.parent;
    return node ? lods.indexOf(node) : null;
  },
  /**
   * Where the world point `point` shows on the page (CSS pixels); null where the camera does not
   * see it (behind it, or beyond its far plane).
   */
  screenPoint(point) {
    const ndc = new THREE.Vector3(...point).sub(origin).project(camera);
    if (Math.abs(ndc.z) > 1) return null;
    const rect = renderer.domElement.getBoundingClientRect();
    return {
      x: rect.left + ((ndc.x + 1) / 2) * rect.width,
      y: rect.top + ((1 - ndc.y) / 2) * rect.height,
    };
  },
};

start(backend);
