// glTF part: three.js draws each MSFT_lod chain as a THREE.LOD whose levels switch at the chain's
// cutoffs (extras.lodconvert), points sized as lodconvert sizes them and lit like the mesh. The
// library is imported in load(), so that a wrong library URL is reported on the page.

const halfFov = (config.view.fov_y_deg * Math.PI) / 360;
const referenceFocal = config.view.height_px / (2 * Math.tan(halfFov));
const lods = [];
const pointScale = { value: 1 }; // half the drawing buffer's height, set by resize()
let THREE, renderer, scene, camera, controls, origin;

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
