// Orientation: the axes triad drawn in a corner of every view (it turns with the camera),
// camera reset (the data set's opening camera) and the six standard views, named as in
// ParaView: "+X" looks along +X (the eye on the -X side), and so on.
//
// The triad is computed here from the camera's azimuth, elevation and up axis with the same
// basis the server renders with (chronocl/render/camera.py: UP_BASES, eye_direction,
// _up_vector, look_at), so it shows the data axes of the frame being drawn: with up y, x right,
// y up, z towards the viewer at azimuth = elevation = 0; with up z, x right, z up, y away;
// with up x, y right, x up, z away. The up menu picks that axis; azimuth turns around it.

import { shown, update } from './connection.js';
import { $ } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindOrientation.
let S;

const POLE = 89.9; // the protocol's elevation limit

// For each up axis, the data axes (rows) pointing right, up and towards the viewer at
// azimuth = elevation = 0 (render/camera.py's UP_BASES).
const UP_BASES = {
  x: [[0, 1, 0], [1, 0, 0], [0, 0, -1]],
  y: [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
  z: [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
};

// The standard views: each looks along a data axis (view direction = -eye direction); their
// camera angles depend on the up axis (`viewAngles`).
export const STANDARD_VIEWS = {
  '+x': { eye: [-1, 0, 0], label: '+X', title: 'look along +X (from the −X side)' },
  '-x': { eye: [1, 0, 0], label: '−X', title: 'look along −X (from the +X side)' },
  '+y': { eye: [0, -1, 0], label: '+Y', title: 'look along +Y (from the −Y side)' },
  '-y': { eye: [0, 1, 0], label: '−Y', title: 'look along −Y (from the +Y side)' },
  '+z': { eye: [0, 0, -1], label: '+Z', title: 'look along +Z (from the −Z side)' },
  '-z': { eye: [0, 0, 1], label: '−Z', title: 'look along −Z (from the +Z side)' },
};

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const round = (v) => Math.round(v * 1e9) / 1e9 + 0; // + 0: no -0

// Azimuth and elevation that put the eye along the data direction `eye` with up axis `up`:
// with up y, +X is (-90, 0), -Y (0, 89.9), +Z (180, 0).
export function viewAngles(eye, up = 'y') {
  const [r, u, t] = UP_BASES[up].map((row) => dot(row, eye));
  if (Math.abs(u) > 0.999) return { azimuth: 0, elevation: u > 0 ? POLE : -POLE };
  return { azimuth: round((Math.atan2(r, t) * 180) / Math.PI), elevation: round((Math.asin(u) * 180) / Math.PI) };
}

export const triad = { shown: true };

function setCamera(fields) {
  if (!S.state) return;
  update({ camera: { ...shown('camera'), ...fields } }, 'full');
  drawTriads();
}

// The opening camera of the data set (projection kept), framing what is visible now.
export function resetCamera() {
  if (!S.initialCamera) return;
  const { azimuth, elevation, zoom, fov } = S.initialCamera;
  update({ camera: { ...shown('camera'), azimuth, elevation, zoom, fov }, refocus: true }, 'full');
  delete S.state.refocus; // a request, not part of the view
  drawTriads();
}

// A standard view at the opening zoom, so the same key always gives the same frame.
export function standardView(name) {
  const v = STANDARD_VIEWS[name];
  if (!v || !S.initialCamera || !S.state) return;
  setCamera({ ...viewAngles(v.eye, shown('camera').up), zoom: S.initialCamera.zoom });
}

// The data axis drawn upwards (the up menu): the angles are kept, so the view turns.
export function setUp(axis) {
  if (!UP_BASES[axis]) return;
  setCamera({ up: axis });
}

export function toggleTriad() {
  triad.shown = !triad.shown;
  $('triad-on').checked = triad.shown;
  drawTriads();
}

// Screen right (s), screen up (u) and towards-the-eye (e) vectors for the camera, in data axes.
function basis(cam) {
  const az = (cam.azimuth * Math.PI) / 180;
  const el = (cam.elevation * Math.PI) / 180;
  const o = [Math.cos(el) * Math.sin(az), Math.sin(el), Math.cos(el) * Math.cos(az)];
  const B = UP_BASES[cam.up || 'y'];
  const e = [0, 1, 2].map((i) => B[0][i] * o[0] + B[1][i] * o[1] + B[2][i] * o[2]);
  // Looking straight along the up axis, the axis towards the viewer at azimuth 0 stands in.
  const up = o[1] > 0.999 ? B[2].map((c) => -c) : o[1] < -0.999 ? B[2] : B[1];
  const f = e.map((c) => -c);
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  let s = cross(f, up);
  const n = Math.hypot(...s);
  s = s.map((c) => c / n);
  return { s, u: cross(s, f), e };
}

// The clip normal `n` turned by a drag of (dx, dy) pixels with camera `cam`: about the screen's
// up axis by dx and its right axis by dy, half a degree a pixel, as the plane would follow the
// pointer when seen through the view.
export function turnedNormal(n, cam, dx, dy) {
  const { s, u } = basis(cam);
  const turn = (v, axis, deg) => {
    const a = (deg * Math.PI) / 180;
    const [c, sn] = [Math.cos(a), Math.sin(a)];
    const d = axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2];
    const x = [axis[1] * v[2] - axis[2] * v[1], axis[2] * v[0] - axis[0] * v[2], axis[0] * v[1] - axis[1] * v[0]];
    return v.map((vi, i) => vi * c + x[i] * sn + axis[i] * d * (1 - c));
  };
  const len = Math.hypot(...n) || 1;
  const out = turn(turn(n.map((c) => c / len), u, dx * 0.5), s, dy * 0.5);
  const m = Math.hypot(...out) || 1;
  return out.map((c) => Math.max(-1, Math.min(1, c / m)));
}

const AXES = [
  { name: 'x', colour: '#ff5a5a' },
  { name: 'y', colour: '#5ad65a' },
  { name: 'z', colour: '#5a9bff' },
];

function drawTriad(canvas, cam) {
  const dpr = window.devicePixelRatio || 1;
  const size = canvas.clientWidth || 64;
  if (canvas.width !== Math.round(size * dpr)) {
    canvas.width = Math.round(size * dpr);
    canvas.height = Math.round(size * dpr);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, size, size);
  canvas.hidden = !triad.shown;
  if (!triad.shown) return;
  const { s, u, e } = basis(cam);
  const c = size / 2;
  const r = size * 0.34;
  // Farthest axis first, so the nearer ones are drawn over it.
  const order = AXES.map((a, i) => ({ ...a, x: s[i], y: u[i], z: e[i] })).sort((a, b) => a.z - b.z);
  ctx.lineCap = 'round';
  ctx.font = `bold ${Math.round(size * 0.19)}px system-ui, sans-serif`;
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  for (const a of order) {
    const x = c + a.x * r;
    const y = c - a.y * r;
    ctx.globalAlpha = a.z < -0.2 ? 0.55 : 1; // pointing away from the viewer
    ctx.strokeStyle = 'rgba(0,0,0,0.7)';
    ctx.lineWidth = 4.5;
    ctx.beginPath();
    ctx.moveTo(c, c);
    ctx.lineTo(x, y);
    ctx.stroke();
    ctx.strokeStyle = a.colour;
    ctx.lineWidth = 2.5;
    ctx.stroke();
    const lx = c + a.x * (r + size * 0.12);
    const ly = c - a.y * (r + size * 0.12);
    ctx.lineWidth = 3;
    ctx.strokeStyle = 'rgba(0,0,0,0.75)';
    ctx.strokeText(a.name, lx, ly);
    ctx.fillStyle = a.colour;
    ctx.fillText(a.name, lx, ly);
  }
  ctx.globalAlpha = 1;
  canvas.dataset.camera = `${cam.azimuth},${cam.elevation}`;
  canvas.dataset.up = cam.up || 'y';
}

// Every view's triad (views.js puts one in each panel's foot band), for the page's current
// camera. Found in the page, so that this module needs nothing from views.js, which needs it.
export function drawTriads() {
  if (!S.state) return;
  // each view's under its camera (its own where it has one)
  $('views').querySelectorAll('.view .triad').forEach((c, i) => drawTriad(c, shown('camera', i)));
}

export function bindOrientation(page) {
  ({ S } = page);
  $('reset-camera').addEventListener('click', resetCamera);
  const box = $('std-views');
  for (const [name, v] of Object.entries(STANDARD_VIEWS)) {
    const b = document.createElement('button');
    b.className = 'mini';
    b.dataset.view = name;
    b.textContent = v.label;
    b.title = `${v.title} [${name.startsWith('-') ? `Shift+${name[1].toUpperCase()}` : name[1]}]`;
    b.addEventListener('click', () => standardView(name));
    box.appendChild(b);
  }
  $('up').addEventListener('change', () => setUp($('up').value));
  $('triad-on').addEventListener('change', () => {
    triad.shown = $('triad-on').checked;
    drawTriads();
  });
}
