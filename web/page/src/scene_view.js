// The 3D view (three.js): the deformed surfaces of every mesh, tinted where the tissue moved
// (|u| from 0 to displacementScaleM: from the tissue colour to yellow), each station's tool
// coloured by its force with the paper's rule, a camera that frames the scene once and then
// follows the user's mouse (orbit, zoom, pan). Renders only when something changed. Units: m.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { forceColour } from './colour.js';
import { DeformationDecoder } from './protocol.js';

const TISSUE = new THREE.Color(0xd8b4a0);  // the host (lowest priority): brain, cube
const VESSEL = new THREE.Color(0xc0392b);  // embedded meshes (higher priority): artery, cylinder
const MOVED = new THREE.Color(0xffd24a);   // tint of tissue displaced by displacementScaleM
const HOST_OPACITY = 0.5;       // see the embedded meshes through the host
const TIP_RADIUS_M = 0.0025;    // tool drawing (the wire carries the pose, not the shape)
const SHAFT_RADIUS_M = 0.0012;
const SHAFT_LENGTH_M = 0.06;
// From the scene's centre towards the camera: the right (+x) side, where the bundled scenes are
// pressed (the brain's right lateral surface, the cube's right face), from the front and above.
const VIEW_DIRECTION = new THREE.Vector3(1.5, -1, 0.8).normalize();

export class SceneView {
  constructor(container, { forceUnitN = 1, displacementScaleM = 0.005 } = {}) {
    this.forceUnitN = forceUnitN;
    this.displacementScaleM = displacementScaleM;
    this.renderer = new THREE.WebGLRenderer({ antialias: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x15171c);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.001, 10);
    this.camera.up.set(0, 0, 1);  // the scenes' z is up (the cube and the brain rest on it)
    this.scene.add(this.camera);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 1.2));
    const headlight = new THREE.DirectionalLight(0xffffff, 1.8);
    headlight.position.set(0.3, 0.6, 1);
    this.camera.add(headlight);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => { this.dirty = true; });
    this.meshes = [];            // by mesh index
    this.tools = new Map();      // station id → THREE.Group
    this.toolVisible = true;
    this.paused = false;          // frames are decoded but the view keeps what it shows
    this.lastStations = null;
    this.sceneName = null;
    this.dirty = true;
    this.container = container;
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
    const loop = () => {
      if (this.dirty) {
        this.dirty = false;
        this.renderer.render(this.scene, this.camera);
      }
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  resize() {
    const w = Math.max(this.container.clientWidth, 1), h = Math.max(this.container.clientHeight, 1);
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  // A new topology (JSON "topology" message and the parsed geometry of every mesh): the meshes
  // are rebuilt; the camera is framed on the first topology of a scene only.
  setTopology(topology, geometries) {
    for (const m of this.meshes) {
      this.scene.remove(m.object);
      m.object.geometry.dispose();
      m.object.material.dispose();
    }
    this.meshes = [];
    const lowest = Math.min(...topology.meshes.map((m) => m.priority ?? 0));
    const several = topology.meshes.length > 1;
    for (const info of topology.meshes) {
      const g = geometries[info.index];
      const geometry = new THREE.BufferGeometry();
      const positions = new Float32Array(g.rest);
      geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
      geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(g.triangles), 1));
      geometry.computeVertexNormals();
      const host = several && (info.priority ?? 0) === lowest;
      const base = host || !several ? TISSUE : VESSEL;
      const colours = new Float32Array(positions.length);
      for (let i = 0; i < colours.length; i += 3) base.toArray(colours, i);
      geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
      const material = new THREE.MeshPhongMaterial({
        vertexColors: true,
        shininess: 20,
        transparent: host,
        opacity: host ? HOST_OPACITY : 1,
        depthWrite: !host,
        side: THREE.DoubleSide,
      });
      const object = new THREE.Mesh(geometry, material);
      object.renderOrder = host ? 1 : 0;  // the transparent host after the opaque meshes
      object.frustumCulled = false;       // its bounds change with every frame
      this.scene.add(object);
      this.meshes[info.index] = {
        id: info.id,
        rest: new Float32Array(g.rest),
        base,
        decoder: new DeformationDecoder(info.vertices),
        object,
        frames: 0,
        maxDisplacementM: 0,
      };
    }
    if (topology.scene !== this.sceneName) {
      this.sceneName = topology.scene;
      this.frame();
    }
    this.dirty = true;
  }

  // Frames the whole scene from VIEW_DIRECTION.
  frame() {
    const box = new THREE.Box3();
    for (const m of this.meshes) {
      m.object.geometry.computeBoundingBox();
      box.union(m.object.geometry.boundingBox);
    }
    if (box.isEmpty()) return;
    const centre = box.getCenter(new THREE.Vector3());
    const radius = box.getSize(new THREE.Vector3()).length() / 2;
    const distance = radius / Math.sin(THREE.MathUtils.degToRad(this.camera.fov) / 2);
    this.camera.position.copy(centre).addScaledVector(VIEW_DIRECTION, distance);
    this.camera.near = distance / 100;
    this.camera.far = distance * 10;
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.update();
  }

  // A parsed deformation frame: the mesh's vertices move to rest + u (when not paused). False
  // when the frame does not fit (another generation or mesh, or a delta without its FULL frame).
  applyFrame(h) {
    const m = this.meshes[h.meshIndex];
    if (!m || !m.decoder.decode(h)) return false;
    m.frames += 1;
    m.maxDisplacementM = h.maxDisplacement;
    if (!this.paused) this.showDisplacement(m);
    return true;
  }

  showDisplacement(m) {
    const pos = m.object.geometry.attributes.position;
    const col = m.object.geometry.attributes.color;
    const p = pos.array, c = col.array, rest = m.rest, u = m.decoder.u, b = m.base;
    for (let i = 0; i < p.length; i += 3) {
      p[i] = rest[i] + u[i];
      p[i + 1] = rest[i + 1] + u[i + 1];
      p[i + 2] = rest[i + 2] + u[i + 2];
      const t = Math.min(Math.hypot(u[i], u[i + 1], u[i + 2]) / this.displacementScaleM, 1);
      c[i] = b.r + t * (MOVED.r - b.r);
      c[i + 1] = b.g + t * (MOVED.g - b.g);
      c[i + 2] = b.b + t * (MOVED.b - b.b);
    }
    pos.needsUpdate = true;
    col.needsUpdate = true;
    m.object.geometry.computeVertexNormals();
    this.dirty = true;
  }

  // Paused, the view keeps showing what it shows (the trainer points at something); frames are
  // still decoded, and the newest state is shown on resume.
  setPaused(paused) {
    this.paused = paused;
    if (!paused) {
      for (const m of this.meshes) if (m) this.showDisplacement(m);
      if (this.lastStations) this.setStations(this.lastStations);
    }
  }

  // Stations (JSON "stations" list): one tool per station, tip sphere and shaft along the axis,
  // coloured by |F| with the paper's rule.
  setStations(stations) {
    this.lastStations = stations;
    if (this.paused) return;
    const seen = new Set();
    for (const s of stations) {
      seen.add(s.id);
      let tool = this.tools.get(s.id);
      if (!tool) {
        tool = makeTool();
        this.tools.set(s.id, tool);
        this.scene.add(tool);
      }
      const [r, g, b] = forceColour(s.force_magnitude_n, this.forceUnitN);
      for (const part of tool.children) part.material.color.setRGB(r, g, b);
      const tip = new THREE.Vector3(...s.tip_m);
      const axis = new THREE.Vector3(...s.axis).normalize();
      tool.position.copy(tip);
      tool.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), axis);
      tool.visible = this.toolVisible;
    }
    for (const [id, tool] of this.tools) {
      if (!seen.has(id)) {
        this.scene.remove(tool);
        for (const part of tool.children) { part.geometry.dispose(); part.material.dispose(); }
        this.tools.delete(id);
      }
    }
    this.dirty = true;
  }

  setToolVisible(visible) {
    this.toolVisible = visible;
    for (const tool of this.tools.values()) tool.visible = visible;
    this.dirty = true;
  }

  // Where a scene point (m) is drawn, in CSS pixels of the page.
  project(p) {
    const v = new THREE.Vector3(...p).project(this.camera);
    const r = this.renderer.domElement.getBoundingClientRect();
    return { x: r.left + (v.x + 1) / 2 * r.width, y: r.top + (1 - v.y) / 2 * r.height };
  }

  // |u| over the vertices of a mesh (m): count, median, 99th percentile, maximum.
  displacementStats(meshIndex) {
    const m = this.meshes[meshIndex];
    if (!m) return null;
    const u = m.decoder.u, n = u.length / 3, mags = new Float64Array(n);
    for (let i = 0; i < n; ++i) mags[i] = Math.hypot(u[3 * i], u[3 * i + 1], u[3 * i + 2]);
    mags.sort();
    const at = (p) => mags[Math.min(n - 1, Math.max(0, Math.ceil(p * n) - 1))];
    return { count: n, p50: at(0.5), p99: at(0.99), max: n ? mags[n - 1] : 0 };
  }

  canvasRect() {
    const r = this.renderer.domElement.getBoundingClientRect();
    return { x: r.left, y: r.top, width: r.width, height: r.height };
  }
}

// Tip sphere at the origin, shaft along +y from the sphere (the group is turned onto the axis).
function makeTool() {
  const group = new THREE.Group();
  const tip = new THREE.Mesh(new THREE.SphereGeometry(TIP_RADIUS_M, 24, 16),
    new THREE.MeshPhongMaterial({ shininess: 60 }));
  const shaft = new THREE.Mesh(
    new THREE.CylinderGeometry(SHAFT_RADIUS_M, SHAFT_RADIUS_M, SHAFT_LENGTH_M, 16),
    new THREE.MeshPhongMaterial({ shininess: 60 }));
  shaft.position.y = TIP_RADIUS_M + SHAFT_LENGTH_M / 2;
  group.add(tip, shaft);
  return group;
}
