// The observer page: connects to neurosim-web, builds the scene from the topology, applies the
// deformation frames, shows each station's tool and force and the server's status. It joins at
// any time (the bridge starts every client from the current state), keeps the last state while
// the server or the bridge is away and picks up a new server's topology.
//
// URL parameters: token (the access token), force_unit (f = |F| / force_unit with F in N in the
// tool colour rule; default 1 N), displacement_scale_mm (|u| at which the surface tint is full;
// default 5 mm).
//
// window.neurosimWeb is for tests and curious users: state(), project([x, y, z]), canvasRect(),
// setToolVisible(bool), setPaused(bool) (as the Pause button), displacementStats(mesh index).
import { Connection } from './connection.js';
import { describeRule } from './colour.js';
import { ForcePlot } from './force_plot.js';
import { KIND_DEFORMATION_FRAME, KIND_MESH_GEOMETRY, kindOf, parseFrame, parseGeometry } from './protocol.js';
import { SceneView } from './scene_view.js';
import { StatusPanel } from './status_panel.js';

const params = new URLSearchParams(window.location.search);
const forceUnitParam = Number(params.get('force_unit'));
const forceUnitN = Number.isFinite(forceUnitParam) && forceUnitParam > 0 ? forceUnitParam : 1;
document.getElementById('force-unit').textContent = String(forceUnitN);
document.getElementById('colour-rule').textContent = describeRule();
const scaleParam = Number(params.get('displacement_scale_mm'));
const displacementScaleMm = Number.isFinite(scaleParam) && scaleParam > 0 ? scaleParam : 5;
document.getElementById('displacement-scale').textContent = String(displacementScaleMm);

const view = new SceneView(document.getElementById('view'),
  { forceUnitN, displacementScaleM: displacementScaleMm / 1000 });
const plot = new ForcePlot(document.getElementById('force-plot'));
const panel = new StatusPanel(document);

const state = {
  connection: 'starting',
  detail: null,
  topology: null,          // the "topology" message of the meshes shown
  pending: null,           // a topology waiting for its geometry messages
  geometries: [],
  framesDecoded: 0,
  framesRejected: 0,
  framesPerS: 0,
  stations: [],
  status: null,
  errors: [],
};
let framesInSecond = 0;
setInterval(() => { state.framesPerS = framesInSecond; framesInSecond = 0; refresh(); }, 1000);

function refresh() {
  const meshes = state.topology ? Math.max(state.topology.meshes.length, 1) : 1;
  panel.setConnection(state.connection, state.detail, state.framesPerS / meshes);
  let banner = null;
  if (state.connection !== 'open') banner = state.detail || 'connecting to the observer bridge';
  else if (state.status && !state.status.server_alive) {
    banner = state.topology ? 'server away: showing the last state' : 'waiting for the server';
  } else if (!state.topology) banner = 'waiting for the scene';
  panel.showBanner(banner);
}

function onText(msg) {
  switch (msg.type) {
    case 'topology':
      state.pending = msg;
      state.geometries = new Array(msg.meshes.length);
      if (msg.meshes.length === 0) completeTopology();
      break;
    case 'status':
      state.status = msg;
      panel.setStatus(msg);
      refresh();
      break;
    case 'stations':
      state.stations = msg.stations;
      view.setStations(msg.stations);
      for (const s of msg.stations) plot.add(s.id, s.force_magnitude_n);
      panel.setStations(msg.stations, (id) => plot.colourOf(id), forceUnitN);
      break;
    case 'refused':
      state.detail = msg.reason;
      break;
    default:
      break;
  }
}

function completeTopology() {
  view.setTopology(state.pending, state.geometries);
  state.topology = state.pending;
  state.pending = null;
  refresh();
}

function onBinary(buffer) {
  try {
    const kind = kindOf(buffer);
    if (kind === KIND_MESH_GEOMETRY) {
      const g = parseGeometry(buffer);
      if (!state.pending || g.generation !== state.pending.generation) return;
      state.geometries[g.meshIndex] = g;
      if (state.geometries.filter(Boolean).length === state.pending.meshes.length) completeTopology();
    } else if (kind === KIND_DEFORMATION_FRAME) {
      const h = parseFrame(buffer);
      if (state.topology && h.generation === state.topology.generation && view.applyFrame(h)) {
        state.framesDecoded += 1;
        framesInSecond += 1;
      } else {
        state.framesRejected += 1;
      }
    }
  } catch (e) {
    if (state.errors.length < 10) state.errors.push(String(e));
  }
}

const pauseButton = document.getElementById('pause');
function setPaused(paused) {
  view.setPaused(paused);
  pauseButton.textContent = paused ? 'Resume view' : 'Pause view';
  pauseButton.classList.toggle('active', paused);
}
pauseButton.addEventListener('click', () => setPaused(!view.paused));

const token = params.get('token');
new Connection({
  token,
  onText,
  onBinary,
  onState: (connection, detail) => {
    state.connection = connection;
    state.detail = detail;
    refresh();
  },
});
refresh();

window.neurosimWeb = {
  state: () => ({
    connection: state.connection,
    detail: state.detail,
    generation: state.topology ? state.topology.generation : 0,
    scene: state.topology ? state.topology.scene : null,
    meshes: view.meshes.filter(Boolean).map((m) => ({
      id: m.id,
      vertices: m.rest.length / 3,
      triangles: m.object.geometry.index.count / 3,
      frames: m.frames,
      maxDisplacementM: m.maxDisplacementM,
    })),
    framesDecoded: state.framesDecoded,
    framesRejected: state.framesRejected,
    paused: view.paused,
    stations: state.stations,
    serverAlive: state.status ? state.status.server_alive : null,
    server: state.status ? state.status.server : null,
    bridge: state.status ? state.status.bridge : null,
    banner: document.getElementById('banner').hidden ? null : document.getElementById('banner').textContent,
    errors: state.errors,
  }),
  project: (p) => view.project(p),
  canvasRect: () => view.canvasRect(),
  setToolVisible: (v) => view.setToolVisible(v),
  setPaused: (v) => setPaused(v),
  displacementStats: (meshIndex) => view.displacementStats(meshIndex),
};
