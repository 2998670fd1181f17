// The 3D view of one exploration: the object's mesh (its COM frame, as exported) and a marker
// per viable approach direction, coloured by manifold like the map pictures. Drag or arrow
// keys rotate, wheel or +/− zoom; clicking a marker shows that pose's grasp. An object on a table
// is drawn at its resting pose above a translucent table (loadTable).
// The live viewer loads this module as it is ("three" through the page's import map); the
// static atlas gets it bundled with three.js into one classic script (bundle/build.mjs), as
// browsers load no module from file://. So: relative imports, and no fetch in here.
import * as THREE from "three";
import { OrbitControls } from "./vendor/OrbitControls.js";
import { OBJLoader } from "./vendor/OBJLoader.js";

function webglAvailable(canvas) {
  try {
    return Boolean(canvas.getContext("webgl2") || canvas.getContext("webgl"));
  } catch {
    return false;
  }
}

export class View3D {
  constructor(canvas, legend, palette, labelName, onPick) {
    this.canvas = canvas;
    this.legend = legend;
    this.palette = palette;
    this.labelName = labelName;
    this.onPick = onPick;
    this.pickShows = "grasp"; // what a click on a marker shows, for the legend
    this.radius = 0.1;
    this.points = null;
    this.poseIds = [];
    // Test the context on a scratch canvas: the renderer logs an error when it cannot get one.
    if (!webglAvailable(document.createElement("canvas"))) {
      throw new Error("this browser gives no WebGL context");
    }
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xfafafa);
    this.camera = new THREE.PerspectiveCamera(40, 4 / 3, 0.001, 100);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(0.35, -0.35, 0.25);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x666666, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.5);
    sun.position.set(1, -1, 2);
    this.scene.add(sun);
    // The object, its axes and the markers, in the object frame; turned to the resting pose
    // when the object lies on a table (loadTable), so that the table stays level.
    this.content = new THREE.Group();
    this.content.add(new THREE.AxesHelper(0.05));
    this.scene.add(this.content);
    this.table = null;
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener("change", () => this.render());
    canvas.addEventListener("keydown", (e) => this.key(e));
    canvas.addEventListener("click", (e) => this.pick(e));
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
  }

  resize() {
    const w = this.canvas.clientWidth || 400;
    const h = this.canvas.clientHeight || 300;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  render() { this.renderer.render(this.scene, this.camera); }

  key(e) {
    const step = Math.PI / 24;
    const offset = this.camera.position.clone().sub(this.controls.target);
    const sph = new THREE.Spherical().setFromVector3(new THREE.Vector3(offset.x, offset.z, -offset.y));
    if (e.key === "ArrowLeft") sph.theta -= step;
    else if (e.key === "ArrowRight") sph.theta += step;
    else if (e.key === "ArrowUp") sph.phi = Math.max(0.05, sph.phi - step);
    else if (e.key === "ArrowDown") sph.phi = Math.min(Math.PI - 0.05, sph.phi + step);
    else if (e.key === "+" || e.key === "=") sph.radius *= 0.85;
    else if (e.key === "-") sph.radius /= 0.85;
    else return;
    e.preventDefault();
    const v = new THREE.Vector3().setFromSpherical(sph);
    this.camera.position.copy(this.controls.target).add(new THREE.Vector3(v.x, -v.z, v.y));
    this.camera.lookAt(this.controls.target);
    this.controls.update();
    this.render();
  }

  // The object's mesh as OBJ text (the `object.obj` export).
  loadMesh(text) {
    const obj = new OBJLoader().parse(text);
    const material = new THREE.MeshStandardMaterial({ color: 0x9a9a9a, roughness: 0.7, flatShading: true });
    obj.traverse((child) => { if (child.isMesh) child.material = material; });
    this.content.add(obj);
    const sphere = new THREE.Box3().setFromObject(obj).getBoundingSphere(new THREE.Sphere());
    this.radius = Math.max(sphere.radius, 0.01);
    this.camera.position.set(3 * this.radius, -3 * this.radius, 2 * this.radius);
    this.camera.near = this.radius / 100;
    this.camera.far = this.radius * 100;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.render();
  }

  loadDirections(d) {
    if (this.points) this.content.remove(this.points);
    const n = d.pose_id.length;
    const positions = new Float32Array(3 * n);
    const colors = new Float32Array(3 * n);
    const counts = new Map();
    const c = new THREE.Color();
    for (let i = 0; i < n; i++) {
      const st = Math.sin(d.theta[i]);
      // Marker where the palm starts: out along the approach direction from the object.
      const rho = 1.08 * this.radius + d.r[i];
      positions.set([rho * st * Math.cos(d.phi[i]), rho * st * Math.sin(d.phi[i]), rho * Math.cos(d.theta[i])], 3 * i);
      const label = d.label[i];
      c.set(label >= 0 ? this.palette[label % 10] : "#000000");
      colors.set([c.r, c.g, c.b], 3 * i);
      counts.set(label, (counts.get(label) || 0) + 1);
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute("color", new THREE.BufferAttribute(colors, 3));
    const material = new THREE.PointsMaterial({ size: this.radius / 12, vertexColors: true });
    this.points = new THREE.Points(geometry, material);
    this.poseIds = d.pose_id;
    this.content.add(this.points);
    this.render();
    const parts = [...counts.entries()].sort((a, b) => a[0] - b[0]).slice(0, 12)
      .map(([label, k]) => `${label >= 0 ? this.labelName(label) : "none"}: ${k}`);
    this.legend.textContent = `${n} of ${d.total_viable} viable poses shown (${parts.join(", ")}). ` +
      `Drag or arrow keys rotate, wheel or +/− zoom, click a marker for its ${this.pickShows}.`;
    this.canvas.dataset.points = String(n);
  }

  // The table under an object at rest on it. `resting` is spec.support.resting: the object
  // frame (centre of mass, object axes) in the table frame, position and quaternion (x, y, z,
  // w). The view's origin stays the centre of mass: the object is turned to its resting pose
  // and the table is the level plane z = -height, a square wide enough for every marker.
  loadTable(resting) {
    const [x, y, z, w] = resting.quaternion;
    this.content.quaternion.set(x, y, z, w);
    const [px, py, height] = resting.position;
    if (this.table) this.scene.remove(this.table);
    const side = 2 * (1.2 * this.radius + 0.12);
    const material = new THREE.MeshStandardMaterial({ color: 0x8c6d46, roughness: 0.9,
      transparent: true, opacity: 0.35, side: THREE.DoubleSide, depthWrite: false });
    this.table = new THREE.Mesh(new THREE.PlaneGeometry(side, side), material);
    this.table.name = "table";
    this.table.position.set(-px, -py, -height);
    this.scene.add(this.table);
    this.canvas.dataset.table = height.toFixed(4);
    this.render();
  }

  pick(e) {
    if (!this.points) return;
    const rect = this.canvas.getBoundingClientRect();
    const mouse = new THREE.Vector2(((e.clientX - rect.left) / rect.width) * 2 - 1,
      -((e.clientY - rect.top) / rect.height) * 2 + 1);
    const ray = new THREE.Raycaster();
    ray.params.Points.threshold = this.radius / 15;
    ray.setFromCamera(mouse, this.camera);
    const hit = ray.intersectObject(this.points)[0];
    if (hit) this.onPick(this.poseIds[hit.index], hit.index);
  }
}
