// The probe plot: v(t) over every step at the voxel a click on a view met, or the mean over
// the box a shift-drag spanned with its min-max band, the window's steps marked on it; and
// its CSV export (the server's, the same columns as `chronocl probe -o curve.csv`). The window
// drawn is the page's current one (it follows play and the brush); switching data sets clears
// the plot.

import { $, canvasSize, fmt } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindProbe.
let S;
let viewer;

export function clearProbe() {
  viewer.probe = null;
  drawProbe();
  $('probe-csv').disabled = true;
  $('probe-text').textContent =
    `click a pixel: v(t) at the voxel where the ray's opacity passes ${S.choices.limits.probe_threshold}`;
}

export function onProbe(msg) {
  viewer.probe = msg;
  drawProbe();
  const txt = $('probe-text');
  $('probe-csv').disabled = !msg.csv;
  if (!msg.values) {
    txt.textContent = msg.x2 === undefined && !msg.box
      ? 'this ray meets no opaque voxel; click on a feature'
      : 'no ray through this box meets an opaque voxel; draw it around a feature';
    return;
  }
  const how = msg.reached ? `opacity passes ${msg.threshold}` : `strongest sample (opacity ${msg.opacity})`;
  if (msg.box) {
    const b = msg.box;
    const n = (b.x[1] - b.x[0]) * (b.y[1] - b.y[0]) * (b.z[1] - b.z[0]);
    txt.textContent =
      `box x ${b.x[0]}:${b.x[1]} y ${b.y[0]}:${b.y[1]} z ${b.z[0]}:${b.z[1]} (${n} voxels): ` +
      `mean, min-max band · view ${msg.view + 1}`;
    return;
  }
  const v = msg.voxel;
  txt.textContent = `voxel x=${v.x} y=${v.y} z=${v.z} (${how}) · view ${msg.view + 1}`;
}

// The probed curve as a CSV file, named for the data set and what was probed.
export function exportProbe() {
  const msg = viewer.probe;
  if (!msg || !msg.csv) return;
  const at = msg.box
    ? ['x', 'y', 'z'].map((a) => `${a}${msg.box[a][0]}-${msg.box[a][1]}`).join('_')
    : `x${msg.voxel.x}_y${msg.voxel.y}_z${msg.voxel.z}`;
  const a = document.createElement('a');
  a.href = URL.createObjectURL(new Blob([msg.csv], { type: 'text/csv' }));
  a.download = `${S.info?.name || 'series'}-probe-${at}.csv`;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

export function drawProbe() {
  const c = $('probe');
  const [ctx, w, h] = canvasSize(c);
  ctx.clearRect(0, 0, w, h);
  const msg = viewer.probe;
  if (!S.info || !msg || !msg.values) return;
  const T = msg.values.length;
  const p = { l: 40, r: 6, t: 8, b: 16 };
  const vmin = S.info.vmin;
  const vmax = S.info.vmax > vmin ? S.info.vmax : vmin + 1;
  const X = (s) => p.l + (T > 1 ? s / (T - 1) : 0.5) * (w - p.l - p.r);
  const Y = (v) => h - p.b - ((v - vmin) / (vmax - vmin)) * (h - p.t - p.b);
  const { t0, t1, stride } = S.state.window;
  const win = [];
  for (let s = t0; s < Math.min(t1, T); s += stride) win.push(s);
  if (!win.length) return;
  ctx.fillStyle = 'rgba(240,160,48,0.16)';
  ctx.fillRect(X(win[0]) - 2, p.t, X(win[win.length - 1]) - X(win[0]) + 4, h - p.t - p.b);
  ctx.strokeStyle = '#343941';
  ctx.lineWidth = 1;
  ctx.strokeRect(p.l, p.t, w - p.l - p.r, h - p.t - p.b);
  if (msg.min && msg.max) {
    ctx.beginPath();
    msg.max.forEach((v, s) => (s === 0 ? ctx.moveTo(X(s), Y(v)) : ctx.lineTo(X(s), Y(v))));
    for (let s = T - 1; s >= 0; s--) ctx.lineTo(X(s), Y(msg.min[s]));
    ctx.closePath();
    ctx.fillStyle = 'rgba(127,184,255,0.22)';
    ctx.fill();
  }
  ctx.beginPath();
  msg.values.forEach((v, s) => (s === 0 ? ctx.moveTo(X(s), Y(v)) : ctx.lineTo(X(s), Y(v))));
  ctx.strokeStyle = '#7fb8ff';
  ctx.lineWidth = 1.6;
  ctx.stroke();
  ctx.fillStyle = '#f0a030';
  for (const s of win) {
    ctx.beginPath();
    ctx.arc(X(s), Y(msg.values[s]), 2.6, 0, 2 * Math.PI);
    ctx.fill();
  }
  ctx.fillStyle = '#8b949e';
  ctx.font = '10px system-ui, sans-serif';
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  ctx.fillText(String(fmt(vmax)), p.l - 3, p.t + 3);
  ctx.fillText(String(fmt(vmin)), p.l - 3, h - p.b - 2);
  ctx.textBaseline = 'bottom';
  ctx.textAlign = 'left';
  const labels = S.info.time_labels;
  ctx.fillText(labels ? labels[0] : 't = 0', p.l, h);
  ctx.textAlign = 'right';
  ctx.fillText(labels ? labels[T - 1] : String(T - 1), w - p.r, h);
  c.dataset.drawn = String(Number(c.dataset.drawn || 0) + 1);
}

export function bindProbe(page) {
  ({ S, viewer } = page);
  $('probe-csv').addEventListener('click', exportProbe);
}
