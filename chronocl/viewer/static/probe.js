// The probe plot: v(t) over every step at the voxel a click on a view met, or the mean over
// the box a shift-drag spanned with its min-max band, the window's steps marked on it; and
// its CSV export (the server's, the same columns as `chronocl probe -o curve.csv`). The window
// drawn is the page's current one (it follows play and the brush); switching data sets clears
// the plot. The plot itself is plot.js's (the events panel draws its tracks with it too).

import { drawTimePlot, windowSteps } from './plot.js';
import { $ } from './state.js';

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
      `mean, min-max band${msg.pinned === 'code' ? ' (probed from code)' : ''} · view ${msg.view + 1}`;
    return;
  }
  const v = msg.voxel;
  const found = { slice: 'pinned on the slice', code: 'probed from code' }[msg.pinned] || how;
  txt.textContent = `voxel x=${v.x} y=${v.y} z=${v.z} (${found}) · view ${msg.view + 1}`;
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
  const msg = viewer.probe;
  if (!S.info || !msg || !msg.values) {
    drawTimePlot(c, {}); // cleared
    return;
  }
  const T = msg.values.length;
  drawTimePlot(c, {
    T, lo: S.info.vmin, hi: S.info.vmax, values: msg.values, min: msg.min, max: msg.max,
    steps: windowSteps(S.state.window, T), labels: S.info.time_labels,
  });
}

export function bindProbe(page) {
  ({ S, viewer } = page);
  $('probe-csv').addEventListener('click', exportProbe);
}
