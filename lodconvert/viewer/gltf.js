// glTF part: three.js draws each MSFT_lod chain as a THREE.LOD whose levels switch at the chain's
// cutoffs (extras.lodconvert), points sized as lodconvert sizes them and lit like the mesh; a
// LOD parent (cell) is a THREE.LOD too, whose first level holds its members' LODs (objects', or
// finer cells') and whose second is its far node; a ray through the clicked pixel picks the
// nearest level shown, and so its object, whose levels it tints. The library is imported in
// load(), so that a wrong library URL is reported on the page.

const halfFov = (config.view.fov_y_deg * Math.PI) / 360;
const referenceFocal = config.view.height_px / (2 * Math.tan(halfFov));
const lods = []; // per object
const cellLods = []; // per cell
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

/** Distance of the camera from where `lod` lies. */
const cameraDistance = (lod) => camera.position.distanceTo(lod.getWorldPosition(new THREE.Vector3()));

function render() {
  renderer.render(scene, camera); // also picks the level of each LOD drawn
  lods.forEach((lod, i) => update(i, lod.getCurrentLevel(), cameraDistance(lod)));
  cellLods.forEach((lod, i) => updateCell(i, lod.getCurrentLevel(), cameraDistance(lod)));
}

function resize(host) {
  camera.aspect = host.clientWidth / host.clientHeight;
  camera.updateProjectionMatrix();
  renderer.setSize(host.clientWidth, host.clientHeight);
  pointScale.value = renderer.getDrawingBufferSize(new THREE.Vector2()).y / 2;
  render();
}

/** Draw and pick the points under `level` at `size` (none: a mesh level, left as it is). */
function sizePoints(level, size) {
  if (!size) return;
  level.traverse((part) => {
    if (part.isPoints) {
      part.material = pointsMaterial(part.material, size);
      pickLikeDrawn(part, size);
    }
  });
}

/**
 * A THREE.LOD at `center` (world coordinates) showing `levels` in turn from 0 and from each of
 * `cutoffs` on (times the LOD scale), then nothing beyond the last cutoff of a `culled` one.
 */
function makeLod(center, levels, cutoffs, culled) {
  const lod = new THREE.LOD();
  lod.position.set(...center).sub(origin);
  lod.userData.cutoffs = [0, ...cutoffs];
  const all = culled ? [...levels, new THREE.Object3D()] : levels;
  all.forEach((level, k) => lod.addLevel(level, lod.userData.cutoffs[k] * lodScale));
  return lod;
}

/** A node's geometry, in its object's source axes, turned into the scene's (see `rotation`). */
function turn(node) {
  const [a, b, c] = rotation;
  node.quaternion.setFromRotationMatrix(new THREE.Matrix4().set(...a, 0, ...b, 0, ...c, 0, 0, 0, 0, 1));
}

async function buildLod(gltf, object) {
  const levels = [];
  for (const [k, index] of [object.node, ...object.ids].entries()) {
    const level = await gltf.parser.getDependency("node", index);
    turn(level);
    level.position.set(...turned(object.local_center)).negate(); // geometry is relative to the origin
    sizePoints(level, object.points[k]);
    levels.push(level);
  }
  return makeLod(object.center, levels, object.cutoffs, object.culled);
}

/** The LOD of `cell`, holding `members` (THREE.LODs placed in the page's coordinates). */
async function buildCellLod(gltf, cell, members) {
  const near = new THREE.Group();
  for (const member of members) near.add(member);
  const far = await gltf.parser.getDependency("node", cell.far);
  sizePoints(far, cell.points);
  const lod = makeLod(cell.center, [near, far], cell.cutoffs, cell.culled);
  near.position.copy(lod.position).negate(); // the members stay where they are
  turn(far);
  far.position.set(...turned(far.position.toArray())); // from the cell's origin (scene units)
  far.position.sub(new THREE.Vector3(...cell.center));
  return lod;
}

/**
 * Build the LODs of the objects and cells; the cells nest (a cell's members are the LODs of
 * the objects or cells whose `cell` or `parent` it is), the outermost go into the scene.
 */
async function buildScene(gltf) {
  for (const object of config.objects) lods.push(await buildLod(gltf, object));
  const members = cells.map(() => []);
  const place = (lod, holder) => (holder === null ? scene.add(lod) : members[holder].push(lod));
  config.objects.forEach((object, k) => place(lods[k], object.cell));
  for (let i = cells.length - 1; i >= 0; i--) { // the finer cells a cell holds come after it
    cellLods[i] = await buildCellLod(gltf, cells[i], members[i]);
    place(cellLods[i], cells[i].parent);
  }
}

/** The emissive colour and intensity that highlight the clicked object. */
const HIGHLIGHT = { color: 0xff9900, intensity: 0.6 };
/** [part, its own material] of each part the highlight tints (on a copy of its material). */
let highlighted = [];

/**
 * A copy of `material` tinted by HIGHLIGHT: glowing where it has an emissive colour (lit
 * meshes and points), else in that colour; a point level's copy keeps its point size.
 */
function tinted(material) {
  const copy = material.clone();
  copy.onBeforeCompile = material.onBeforeCompile;
  if (copy.emissive) {
    copy.emissive.set(HIGHLIGHT.color);
    copy.emissiveIntensity = HIGHLIGHT.intensity;
  } else copy.color.set(HIGHLIGHT.color);
  return copy;
}

/**
 * Tint every level of object `index` (null: none), restoring the parts tinted before. The
 * parts get tinted copies of their materials: the writer shares one material among all parts
 * of a colour, of every object.
 */
function highlightObject(index) {
  for (const [part, material] of highlighted) {
    [part.material].flat().forEach((copy) => copy.dispose());
    part.material = material;
  }
  highlighted = [];
  lods[index]?.traverse((part) => {
    if (!part.material) return;
    highlighted.push([part, part.material]);
    const { material } = part;
    part.material = Array.isArray(material) ? material.map(tinted) : tinted(material);
  });
  render();
}

/** Switch every LOD at `scale` times its cutoffs. */
function scaleLods(scale) {
  for (const lod of [...lods, ...cellLods]) {
    lod.levels.forEach((level, k) => { level.distance = lod.userData.cutoffs[k] * scale; });
  }
}

const backend = {
  async load(host) {
    let GLTFLoader, KTX2Loader, OrbitControls, MeshoptDecoder;
    [THREE, { GLTFLoader }, { KTX2Loader }, { OrbitControls }, { MeshoptDecoder }] =
      await Promise.all([
        import("three"),
        import("three/addons/loaders/GLTFLoader.js"),
        import("three/addons/loaders/KTX2Loader.js"), // --texture-format ktx2
        import("three/addons/controls/OrbitControls.js"),
        import("three/addons/libs/meshopt_decoder.module.js"), // --compress meshopt
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
    const ktx2 = new KTX2Loader() // Basis Universal's transcoder, beside three's addons
      .setTranscoderPath(import.meta.resolve("three/addons/libs/basis/"))
      .detectSupport(renderer);
    const loader = new GLTFLoader().setMeshoptDecoder(MeshoptDecoder).setKTX2Loader(ktx2);
    await buildScene(await loader.loadAsync(config.asset));
    raycaster = new THREE.Raycaster();
    controls = new OrbitControls(camera, renderer.domElement);
    controls.addEventListener("change", render);
    window.addEventListener("resize", () => resize(host));
    camera.position.set(...viewDirection);
    resize(host);
  },
  async setDistance(distance) {
    const direction = camera.position.clone().sub(controls.target).normalize();
    camera.position.copy(controls.target).addScaledVector(direction, distance);
    controls.update();
    render();
    await nextFrame();
  },
  /** Switch at `scale` times every cutoff (drawn by the next move), seeing to the slider's end. */
  setLodScale(scale) {
    scaleLods(scale);
    camera.far = 10 * farthest;
    camera.updateProjectionMatrix();
  },
  highlight: highlightObject,
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
