// The header bar and side panel controls: number of views, projection, background, time TF,
// enhancement, threshold, slicing plane, save. Their menus, defaults and bounds come from the
// server's `info` message (`fillControls`), so nothing here copies a list from the server.

import { LINKABLE, send, shown, update } from './connection.js';
import { $ } from './state.js';
import { syncPointColor } from './tf_editor.js';
import { fillSelect, layoutViews } from './views.js';

// The page's state (state.js: pageState), made by app.js and given to bindControls.
let S;

const TIME_PARAMS = ['center', 'width', 'floor']; // the sliders t-center, t-width, t-floor

function setRange(id, [lo, hi]) {
  $(id).min = lo;
  $(id).max = hi;
}

// The menus and input bounds, from the server's choices.
export function fillControls(c) {
  fillSelect($('nviews'), Array.from({ length: c.limits.max_views }, (_, k) => k + 1));
  fillSelect($('projection'), c.projections);
  fillSelect($('up'), c.up_axes);
  fillSelect($('background'), c.backgrounds);
  fillSelect($('time-color'), c.time_colors);
  fillSelect($('time-alpha'), c.time_alphas);
  fillSelect($('positions'), c.positions);
  fillSelect($('enhance'), c.enhance);
  for (const p of TIME_PARAMS) setRange(`t-${p}`, c.ranges.time_tf[p]);
  for (const k of ['k0', 'k1', 'k2']) setRange(k, c.ranges.enhance[k]);
  setRange('threshold', c.ranges.threshold);
  setRange('clip-offset', c.ranges.clip.offset);
  $('probe-text').textContent =
    `click a pixel: v(t) at the voxel where the ray's opacity passes ${c.limits.probe_threshold}`;
}

export function syncControls() {
  const st = S.state;
  $('nviews').value = st.views.length;
  const camera = shown('camera'); // the selected view's (its own where it has one)
  $('projection').value = camera.projection;
  $('up').value = camera.up;
  $('background').value = st.background;
  $('outline').checked = st.outline;
  const t = shown('time_tf'); // the selected view's (its own where it has one)
  $('time-color').value = t.color;
  $('time-alpha').value = t.alpha;
  for (const p of TIME_PARAMS) $(`t-${p}`).value = t[p];
  $('positions').value = t.positions;
  // whose TF the editors edit: the selected view's own, where it has one
  for (const k of ['time_tf', 'data_tf']) {
    const own = !!(st.views[S.selectedView] || {})[k];
    $(`own-${k}`).hidden = !own;
    $(`own-${k}`).textContent = own ? `· view ${S.selectedView + 1}'s own` : '';
  }
  $('enhance').value = st.enhance.kind;
  $('k0').value = st.enhance.k0;
  $('k1').value = st.enhance.k1;
  $('k2').value = st.enhance.k2;
  $('threshold').value = st.threshold;
  $('clip-on').checked = !!st.clip;
  if (st.clip) {
    const axis = st.clip.normal.map((c) => Math.round(c * 1e6) / 1e6).join(',');
    const known = [...$('clip-axis').options].some((o) => o.value === axis);
    $('clip-axis').value = known ? axis : 'custom';
  }
  $('stride').value = st.window.stride;
  syncTimeControls();
  syncPointColor();
}

// Only the sliders the chosen opacity shape reads are enabled.
function syncTimeControls() {
  const shape = S.choices.time_alphas.find((a) => a.name === shown('time_tf').alpha);
  const used = new Set(shape ? shape.params : []);
  for (const p of TIME_PARAMS) $(`t-${p}`).disabled = !used.has(p);
}

// A new view is a copy of the selected view (else the last): its mode and order, and its
// camera, data TF and time TF (a copy of its own where it has one, else linked, as it is), so
// two windows of one mode compare at once (type a window into the new view's header). It
// follows the timeline's window.
function newView(views) {
  const from = views[S.selectedView] || views[views.length - 1];
  const view = { mode: from.mode, order: from.order || S.choices.orders[0] };
  for (const k of LINKABLE) view[k] = from[k] ? JSON.parse(JSON.stringify(from[k])) : null;
  return view;
}

const within = (v, [lo, hi]) => Number.isFinite(v) && v >= lo && v <= hi;

export function bindControls(page) {
  ({ S } = page);
  $('dataset').addEventListener('change', () => send({ type: 'open', dataset: Number($('dataset').value) }));
  $('nviews').addEventListener('change', () => {
    const n = Number($('nviews').value);
    const views = S.state.views.slice(0, n).map((v) => ({ ...v }));
    while (views.length < n) views.push(newView(views));
    S.state.views = views;
    S.selectedView = Math.min(S.selectedView, n - 1);
    const size = layoutViews();
    update({ views, size });
  });
  $('projection').addEventListener('change', () =>
    update({ camera: { ...shown('camera'), projection: $('projection').value } }));
  $('background').addEventListener('change', () => update({ background: $('background').value }));
  $('outline').addEventListener('change', () => update({ outline: $('outline').checked }));

  const timeTF = (quality) => {
    const t = {
      color: $('time-color').value,
      alpha: $('time-alpha').value,
      positions: $('positions').value,
    };
    for (const p of TIME_PARAMS) t[p] = Number($(`t-${p}`).value);
    update({ time_tf: Object.assign({}, shown('time_tf'), t) }, quality);
    syncTimeControls();
  };
  for (const id of ['time-color', 'time-alpha', 'positions']) $(id).addEventListener('change', () => timeTF('full'));
  for (const p of TIME_PARAMS) {
    $(`t-${p}`).addEventListener('input', () => timeTF('preview'));
    $(`t-${p}`).addEventListener('change', () => timeTF('full'));
  }

  $('enhance').addEventListener('change', () => {
    const kind = $('enhance').value;
    const [k0, k1, k2] = S.choices.enhance.find((e) => e.name === kind).k;
    $('k0').value = k0;
    $('k1').value = k1;
    $('k2').value = k2;
    update({ enhance: { kind, k0, k1, k2 } });
  });
  for (const id of ['k0', 'k1', 'k2']) {
    $(id).addEventListener('change', () => {
      const v = Number($(id).value);
      if (within(v, S.choices.ranges.enhance[id])) update({ enhance: { ...S.state.enhance, [id]: v } });
    });
  }
  $('threshold').addEventListener('change', () => {
    const v = Number($('threshold').value);
    if (within(v, S.choices.ranges.threshold)) update({ threshold: v });
  });

  const clip = (quality) => {
    if (!$('clip-on').checked) return update({ clip: null }, quality);
    const custom = $('clip-axis').value === 'custom' && S.state.clip;
    const normal = custom ? S.state.clip.normal : $('clip-axis').value.split(',').map(Number);
    update({ clip: { normal, offset: Number($('clip-offset').value) } }, quality);
  };
  $('clip-on').addEventListener('change', () => clip('full'));
  $('clip-axis').addEventListener('change', () => clip('full'));
  $('clip-offset').addEventListener('input', () => $('clip-on').checked && clip('preview'));
  $('clip-offset').addEventListener('change', () => $('clip-on').checked && clip('full'));

  // Saved as laid out on screen: the same panels per row.
  $('save-image').addEventListener('click', () =>
    send({ type: 'save', what: 'image', columns: S.columns }));
  $('save-cv').addEventListener('click', () =>
    send({ type: 'save', what: 'chronovolume', view: S.selectedView }));
  $('save-movie').addEventListener('click', () => {
    const int = (id, lo, hi) => Math.max(lo, Math.min(hi, Math.round(Number($(id).value)) || lo));
    $('save-movie').disabled = true;
    $('movie-progress').textContent = 'rendering…';
    send({
      type: 'save',
      what: 'movie',
      movie: $('movie-kind').value,
      format: $('movie-format').value,
      frames: int('movie-frames', 2, 360),
      fps: int('movie-fps', 1, 60),
      columns: S.columns,
    });
  });
}

// A movie's frames as they are rendered; its download ends it (app.js), as does an error.
export function movieProgress(msg) {
  $('movie-progress').textContent = msg ? `frame ${msg.done} of ${msg.total}` : '';
  if (!msg || msg.done >= msg.total) $('save-movie').disabled = false;
}
