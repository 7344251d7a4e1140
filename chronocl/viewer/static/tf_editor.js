// The data transfer function editor: a histogram of the window's values (log or linear) under
// the opacity curve and its colour strip; drag points, click to add, double-click to remove,
// wheel to zoom in u; the selected point's value and opacity typed in; a readout of value,
// opacity and count under the pointer; colour-map presets (the server's stops,
// chronocl/core/colormaps.py, applied as `DataTF.with_colormap` does: opacity kept).
//
// A colour map enters the points the server gets as one point per stop (33), so the colours
// follow the map; the editor shows as handles only the opacity curve's own points, and an edit
// of a handle recomputes the stops' opacities from the handles (`mapped`). Which points are
// handles is read off the points themselves (`handles`), so undo, snapshots and the page's
// address need nothing more than the points.
//
// Two scales: the curve's points are over u in [0, 1] of the TF's value range, and the axis
// (the zoom, the histogram, the value labels) is over the series' range. A TF fitted to a
// window (fit.js) has its own range, inside the series': u = 0 and u = 1 of the curve land on
// its lo and hi (`toAxis`), the curve is flat beyond them, and points stay between them.

import { send, shown, update } from './connection.js';
import { $, canvasSize, fmt } from './state.js';
import { followDataTF } from './time_follow.js';

// The page's state (state.js: pageState), made by app.js and given to bindTF.
let S;
let viewer;

const tf = { drag: null };
const pad = { l: 6, r: 6, t: 8, b: 18 };
// X, U: axis u <-> canvas x; PX, PU: a point's u (the TF's range) <-> canvas x.
function tfGeom() {
  const [ctx, w, h] = canvasSize($('tf'));
  const [lo, hi] = S.zoom;
  const X = (u) => pad.l + ((u - lo) / (hi - lo)) * (w - pad.l - pad.r);
  const U = (x) => lo + ((x - pad.l) / (w - pad.l - pad.r)) * (hi - lo);
  const Y = (a) => h - pad.b - a * (h - pad.t - pad.b);
  const A = (y) => (h - pad.b - y) / (h - pad.t - pad.b);
  return { ctx, w, h, X, U, Y, A, PX: (u) => X(toAxis(u)), PU: (x) => fromAxis(U(x)) };
}
const rgbCss = (p, a = 1) => `rgba(${Math.round(p[1] * 255)},${Math.round(p[2] * 255)},${Math.round(p[3] * 255)},${a})`;
// A change mode's data TF maps δ = |Δ| between consecutive steps, scaled to the TF's value
// range (modes/change.py): its axis is the change, from 0 to that range's span, and its
// histogram counts the window's changes (`Dataset.histogram`, of "change").
const values = () => shown('data_tf').value_range || (S.info ? [S.info.vmin, S.info.vmax] : [0, 1]);
const changes = () => S.choices?.modes.find((m) => m.name === shown('mode'))?.data_axis === 'change';
const series = () => {
  if (changes()) return [0, values()[1] - values()[0]];
  return S.info ? [S.info.vmin, S.info.vmax] : [0, 1];
};
// The data value at axis u, and at a point's u.
const dataValue = (g) => series()[0] + g * (series()[1] - series()[0]);
const pointValue = (u) => tfRange()[0] + u * (tfRange()[1] - tfRange()[0]);
// The TF's value range: a fitted TF's [lo, hi], else the series'.
const tfRange = () => (changes() ? series() : shown('data_tf').value_range || series());
// A point's u on the axis, and back.
const toAxis = (u) => (pointValue(u) - series()[0]) / (series()[1] - series()[0] || 1);
const fromAxis = (g) => (dataValue(g) - tfRange()[0]) / (tfRange()[1] - tfRange()[0] || 1);
// A point's u as the same curve over the series' range has it (a fitted curve spread over the
// series, fit.js): its value's place in the series, or a change's place in the series' span.
export function toSeries(u) {
  if (!changes() || !S.info) return toAxis(u);
  return (u * (values()[1] - values()[0])) / (S.info.vmax - S.info.vmin || 1);
}

export function drawTF() {
  if (!S.state) return;
  const { ctx, w, h, X, Y, PX } = tfGeom();
  const pts = shown('data_tf').points;
  const { map, idx } = handles(pts);
  followMap(map, idx);
  ctx.clearRect(0, 0, w, h);
  const hist = S.histogram;
  if (hist && hist.key !== histKey(...S.zoom)) askHistogram(...S.zoom); // another zoom or mode's
  if (hist && hist.key === histKey(...S.zoom)) {
    const n = hist.counts.length;
    const scale = $('hist-log').checked ? Math.log1p : (c) => c;
    const top = scale(Math.max(...hist.counts, 1));
    ctx.fillStyle = 'rgba(120,160,210,0.45)';
    const bw = (w - pad.l - pad.r) / n;
    hist.counts.forEach((c, i) => {
      const bh = (scale(c) / top) * (h - pad.t - pad.b);
      ctx.fillRect(pad.l + i * bw, h - pad.b - bh, Math.max(1, bw - 0.5), bh);
    });
  }
  // Colour strip under the curve: the TF's colour with its opacity.
  const grad = ctx.createLinearGradient(PX(pts[0][0]), 0, PX(pts[pts.length - 1][0]), 0);
  const span = pts[pts.length - 1][0] - pts[0][0] || 1;
  for (const p of pts) grad.addColorStop((p[0] - pts[0][0]) / span, rgbCss(p, 0.25 + 0.75 * p[4]));
  ctx.fillStyle = grad;
  ctx.fillRect(pad.l, h - pad.b + 2, w - pad.l - pad.r, 5);
  // Opacity curve, clipped to the plot (zoomed in, its segments reach far past the edges),
  // and the points within the visible range.
  ctx.save();
  ctx.beginPath();
  ctx.rect(pad.l, 0, w - pad.l - pad.r, h - pad.b + 1);
  ctx.clip();
  if (shown('data_tf').value_range) {
    // A fitted range: its ends, where the curve's first and last points sit.
    ctx.setLineDash([3, 3]);
    ctx.strokeStyle = 'rgba(240,160,48,0.55)';
    ctx.lineWidth = 1;
    for (const u of [0, 1]) {
      ctx.beginPath();
      ctx.moveTo(PX(u), pad.t);
      ctx.lineTo(PX(u), h - pad.b);
      ctx.stroke();
    }
    ctx.setLineDash([]);
  }
  ctx.beginPath();
  ctx.moveTo(X(Math.min(S.zoom[0], toAxis(pts[0][0]))), Y(pts[0][4]));
  for (const p of pts) ctx.lineTo(PX(p[0]), Y(p[4]));
  ctx.lineTo(X(Math.max(S.zoom[1], toAxis(pts[pts.length - 1][0]))), Y(pts[pts.length - 1][4]));
  ctx.strokeStyle = '#f0a030';
  ctx.lineWidth = 1.5;
  ctx.stroke();
  ctx.restore();
  const zspan = S.zoom[1] - S.zoom[0];
  idx.forEach((i) => {
    const p = pts[i];
    const g = toAxis(p[0]);
    if (g < S.zoom[0] - 1e-3 * zspan || g > S.zoom[1] + 1e-3 * zspan) return;
    ctx.beginPath();
    ctx.arc(PX(p[0]), Y(p[4]), i === S.selectedPoint ? 6 : 4.5, 0, 2 * Math.PI);
    ctx.fillStyle = rgbCss(p);
    ctx.fill();
    ctx.lineWidth = i === S.selectedPoint ? 2.5 : 1.2;
    ctx.strokeStyle = i === S.selectedPoint ? '#f0a030' : '#c8ccd2'; // seen round a dark map colour too
    ctx.stroke();
  });
  ctx.fillStyle = '#8b949e';
  ctx.font = '10px system-ui, sans-serif';
  ctx.textBaseline = 'bottom';
  if (S.info) {
    ctx.textAlign = 'left';
    ctx.fillText(String(fmt(dataValue(S.zoom[0]))), pad.l, h);
    ctx.textAlign = 'right';
    ctx.fillText(String(fmt(dataValue(S.zoom[1]))), w - pad.r, h);
    ctx.textAlign = 'left';
    $('zoom-lo').value = fmt(dataValue(S.zoom[0]));
    $('zoom-hi').value = fmt(dataValue(S.zoom[1]));
  }
  noteRange();
}

// The data TF as the server gets it: its points, and its range where it has its own.
export function dataTF(points = shown('data_tf').points, valueRange = shown('data_tf').value_range) {
  const d = { points: points.map((p) => p.slice()) };
  if (valueRange) d.value_range = valueRange.slice();
  return d;
}

function sendTF(quality) {
  update({ data_tf: dataTF() }, quality);
  drawTF();
}

// The line under the editor: the range the curve spans (fitted, or the series'), and what it
// was fitted to; where that is no longer the selected view's mode and window (a mode changed
// after the curve was edited by hand, so not fitted again; the window moved), it says so. Drawn
// with the editor, and after each frame (views.js) and mode change (fit.js).
export function noteRange() {
  if (!S.state) return;
  const vr = shown('data_tf').value_range;
  let text = "curve over the series' range";
  if (vr) {
    text = `curve over ${fmt(vr[0])} … ${fmt(vr[1])}`;
    const f = S.fits.findLast((q) => q.range[0] === vr[0] && q.range[1] === vr[1]);
    if (f) {
      const span = ([t0, t1, stride]) => `window ${t0}:${t1}${stride > 1 ? `:${stride}` : ''}`;
      const fitted = `${f.mode}, ${span(f.window)}`;
      const n = S.state.views.length;
      const i = Math.max(0, Math.min(S.selectedView, n - 1));
      const v = S.state.views[i];
      const w = v.window || S.state.window;
      const now = `${v.mode}, ${span([w.t0, w.t1, w.stride || 1])}`;
      const who = n > 1 ? `view ${i + 1}` : 'the view';
      text += now === fitted ? ` (fitted to ${fitted})` : ` (fitted to ${fitted}; ${who} now shows ${now}: F fits the curve to it)`;
    }
  }
  const el = $('tf-range');
  el.textContent = text;
  el.classList.toggle('stale', !!vr && text.includes(' now shows '));
}

// The selected point's colour, value and opacity into their fields.
export function syncPointColor() {
  const p = shown('data_tf').points[S.selectedPoint];
  if (!p) return;
  const hex = (v) => Math.round(v * 255).toString(16).padStart(2, '0');
  $('point-color').value = `#${hex(p[1])}${hex(p[2])}${hex(p[3])}`;
  if (S.info) $('point-value').value = fmt(pointValue(p[0]));
  $('point-alpha').value = fmt(p[4]);
}

// Piecewise-linear value of column j of sorted points [x, ...] at x (constant beyond the ends).
export function interp(pts, x, j) {
  if (x <= pts[0][0]) return pts[0][j];
  for (let k = 1; k < pts.length; k++) {
    if (x <= pts[k][0]) {
      const [a, b] = [pts[k - 1], pts[k]];
      return b[0] === a[0] ? b[j] : a[j] + ((x - a[0]) / (b[0] - a[0])) * (b[j] - a[j]);
    }
  }
  return pts[pts.length - 1][j];
}

// The points the server gets for opacity handles `hs` ([u, a], sorted) under colour map
// `name`: a point at each handle and each of the map's stops, coloured by the map, with the
// opacity of the handles' curve (on a TF's own points, what `DataTF.with_colormap` gives).
function mapped(hs, name) {
  const stops = S.choices.colormaps[name];
  const us = [...hs.map((q) => q[0]), ...stops.map((q) => q[0])].sort((a, b) => a - b);
  return us
    .filter((u, k) => k === 0 || u - us[k - 1] > 1e-9)
    .map((u) => [u, interp(stops, u, 1), interp(stops, u, 2), interp(stops, u, 3), interp(hs, u, 1)]);
}

const SAME_U = 1e-7; // a stop's position, as the points carry it
const SAME_RGB = 2e-3; // a colour as the map has it (well under 1/255)
const SAME_A = 1e-6; // an opacity on the line between its neighbours'

// The colour map whose colours the points follow: every stop of it among the points and every
// point coloured as the map is at its position; null if none.
function mapOf(pts) {
  for (const [name, stops] of Object.entries((S.choices && S.choices.colormaps) || {})) {
    if (pts.length < stops.length) continue;
    let k = 0;
    const present = stops.every((q) => {
      while (k < pts.length && pts[k][0] < q[0] - SAME_U) k++;
      return k < pts.length && Math.abs(pts[k][0] - q[0]) <= SAME_U;
    });
    if (!present) continue;
    const coloured = pts.every((p) => [1, 2, 3].every((j) => Math.abs(p[j] - interp(stops, p[0], j)) <= SAME_RGB));
    if (coloured) return name;
  }
  return null;
}

// The points the editor shows as handles (indices): all of them, or under a colour map only the
// opacity curve's own points: its two ends (at 0 and 1, as the map's stops are; they keep
// their place), the points off the map's stops and those where the curve bends.
export function handles(pts) {
  const all = pts.map((_, i) => i);
  const map = mapOf(pts);
  if (!map) return { map: null, idx: all };
  const stops = S.choices.colormaps[map];
  const onStop = (u) => stops.some((q) => Math.abs(q[0] - u) <= SAME_U);
  const n = pts.length;
  const bends = (i) => {
    const [a, p, b] = [pts[i - 1], pts[i], pts[i + 1]];
    return Math.abs(p[4] - (a[4] + ((p[0] - a[0]) / (b[0] - a[0])) * (b[4] - a[4]))) > SAME_A;
  };
  return { map, idx: all.filter((i) => i === 0 || i === n - 1 || !onStop(pts[i][0]) || bends(i)) };
}

// Whether handle k of `hs` keeps its value: the ends under a map (the map spans 0 to 1).
const pinned = (hs, map, k) => !!map && (k === 0 || k === hs.length - 1);

// The handles as [u, a] pairs, and which of them is the selected point (-1: none).
function handlePairs(pts) {
  const { map, idx } = handles(pts);
  return { map, idx, hs: idx.map((i) => [pts[i][0], pts[i][4]]), at: idx.indexOf(S.selectedPoint) };
}

// The points for handles `hs` under colour map `map` ([u, a] pairs), or without one (`hs` are
// then the points, [u, r, g, b, a]); handle `sel` (an index into hs) selected. False, and the
// points kept, where the map would need more points than the server takes.
export function setHandles(hs, map, sel) {
  if (!map) {
    shown('data_tf').points = hs;
    S.selectedPoint = sel;
    return true;
  }
  const pts = mapped(hs, map);
  const most = S.choices.limits.max_tf_points;
  if (pts.length > most) {
    $('tf-hover').textContent = `colour map ${map} needs ${pts.length} points; remove some (at most ${most})`;
    return false;
  }
  shown('data_tf').points = pts;
  const u = hs[sel][0];
  S.selectedPoint = pts.findIndex((p) => Math.abs(p[0] - u) <= 1e-9);
  return true;
}

// The colour-map menu names the map the colours follow, the colour field (one point's colour)
// is off under one, and the selected point is a handle (the nearest one).
function followMap(map, idx) {
  $('tf-colormap').value = map || '';
  const picker = $('point-color');
  picker.disabled = !!map;
  picker.title = map
    ? `the colours follow colour map ${map}; choose "none" there to colour the points one by one`
    : "the selected point's colour";
  if (!idx.includes(S.selectedPoint)) {
    const pts = shown('data_tf').points;
    const u = pts[Math.min(S.selectedPoint, pts.length - 1)][0];
    S.selectedPoint = idx.reduce((b, i) => (Math.abs(pts[i][0] - u) < Math.abs(pts[b][0] - u) ? i : b), idx[0]);
    syncPointColor();
  }
}

// The readout at axis u.
function showHover(u) {
  const out = $('tf-hover');
  if (u === null || !S.info) {
    out.innerHTML = '&nbsp;';
    return;
  }
  const pts = shown('data_tf').points;
  const what = changes() ? '|Δ|' : 'value';
  let text = `${what} ${fmt(dataValue(u))} · opacity ${fmt(interp(pts, fromAxis(u), 4))}`;
  const hist = S.histogram;
  if (hist && u >= hist.range[0] && u <= hist.range[1]) {
    const n = hist.counts.length;
    const i = Math.min(n - 1, Math.floor(((u - hist.range[0]) / (hist.range[1] - hist.range[0])) * n));
    text += ` · ${hist.counts[i]} sampled voxels`;
  }
  out.textContent = text;
}

// The colour-map menu, from the server's presets.
export function fillColormaps() {
  const names = Object.keys(S.choices.colormaps);
  const none = new Option('none', '');
  none.title = 'each point has its own colour (leaving a map, the handles keep the colours it gave them)';
  $('tf-colormap').replaceChildren(none, ...names.map((n) => new Option(n, n)));
}

// The note under the histogram: which steps it counts, named against the window, and the
// steps themselves where it samples some of a long window (a window of 10 steps counted from
// 5 of them must not read as a window of 20…28).
export function noteHistogram() {
  const hist = S.histogram;
  if (!hist || !hist.steps) return;
  const s = hist.steps;
  const [t0, t1, stride] = hist.window || [s[0], s[s.length - 1] + 1, 1];
  const n = Math.ceil((t1 - t0) / stride);
  const win = `window ${t0}:${t1}${stride > 1 ? `:${stride}` : ''}`;
  let which = `step ${s[0]}`;
  if (s.length > 1 && s.length >= n) which = `the ${n} steps of ${win}`;
  else if (s.length > 1) which = `${s.length} of the ${n} steps of ${win} (${s.join(', ')})`;
  if (hist.of === 'change') {
    const pairs = s.length === 1 ? `step ${s[0]} from the step before` : `${which}, each from the step before`;
    $('hist-note').textContent = `histogram of |Δ|: ${pairs}; opacity up, change across`;
    return;
  }
  $('hist-note').textContent = `histogram of ${which}; opacity up, value across`;
}

export function bindTF(page) {
  ({ S, viewer } = page);
  // The indices of the points the editor shows as handles, for scripted use (the browser tests).
  viewer.tfHandles = () => handles(shown('data_tf').points).idx;
  // Page coordinates of a TF point's handle, for scripted use (the browser tests).
  viewer.tfPointAt = (i) => {
    const g = tfGeom();
    const r = $('tf').getBoundingClientRect();
    const p = shown('data_tf').points[i];
    return { x: r.left + g.PX(p[0]), y: r.top + g.Y(p[4]) };
  };
  const c = $('tf');
  const at = (e) => {
    const r = c.getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  };
  const clamp01 = (v) => Math.max(0, Math.min(1, v));
  c.addEventListener('pointerdown', (e) => {
    if (!S.state || e.button !== 0) return;
    const g = tfGeom();
    const [x, y] = at(e);
    const pts = shown('data_tf').points;
    // Under a map the drag edits the [u, a] handles; without one, the points themselves.
    const { map, idx, hs } = handlePairs(pts);
    const own = map ? hs : pts.map((p) => p.slice());
    let best = -1;
    let bestD = 9;
    idx.forEach((i, k) => {
      const d = Math.hypot(g.PX(pts[i][0]) - x, g.Y(pts[i][4]) - y);
      if (d < bestD) [best, bestD] = [k, d];
    });
    if (best < 0) {
      // A new handle there (without a map, on the curve's colour at that value); within a
      // fitted range, the curve's ends.
      const u = clamp01(g.PU(x));
      if (own.some((q) => Math.abs(q[0] - u) < 1e-4) || pts.length >= S.choices.limits.max_tf_points) return;
      best = own.findIndex((q) => q[0] > u);
      if (best < 0) best = own.length;
      const a = clamp01(g.A(y));
      own.splice(best, 0, map ? [u, a] : [u, ...[1, 2, 3].map((j) => interp(pts, u, j)), a]);
    }
    if (!setHandles(own, map, best)) return;
    syncPointColor();
    c.setPointerCapture(e.pointerId);
    tf.drag = { k: best, hs: own, map };
    sendTF('preview');
  });
  c.addEventListener('pointermove', (e) => {
    if (!tf.drag) {
      if (S.state) showHover(clamp01(tfGeom().U(at(e)[0])));
      return;
    }
    const g = tfGeom();
    const [x, y] = at(e);
    const { k, hs, map } = tf.drag;
    const A = map ? 1 : 4; // where a handle keeps its opacity
    const lo = k > 0 ? hs[k - 1][0] + 1e-4 : 0;
    const hi = k < hs.length - 1 ? hs[k + 1][0] - 1e-4 : 1;
    if (!pinned(hs, map, k)) hs[k][0] = Math.max(lo, Math.min(hi, clamp01(g.PU(x))));
    hs[k][A] = clamp01(g.A(y));
    if (!setHandles(hs.map((q) => q.slice()), map, k)) return;
    syncPointColor(); // the value and opacity fields follow the point as it moves
    showHover(toAxis(hs[k][0]));
    sendTF('preview');
  });
  const end = () => {
    if (!tf.drag) return;
    tf.drag = null;
    sendTF('full');
  };
  c.addEventListener('pointerup', end);
  c.addEventListener('pointercancel', end);
  c.addEventListener('pointerleave', () => showHover(null));
  // A typed value or opacity for the selected point (only the field typed in: the other
  // shows a rounded number).
  const typed = (field) => () => {
    const pts = shown('data_tf').points;
    const { map, hs, at: k } = handlePairs(pts);
    const own = map ? hs : pts.map((p) => p.slice());
    const A = map ? 1 : 4; // where a handle keeps its opacity
    const p = own[k];
    const v = parseFloat($(field).value);
    if (!p || !S.info || !Number.isFinite(v)) return syncPointColor();
    if (field === 'point-alpha') p[A] = clamp01(v);
    else if (!pinned(own, map, k)) {
      const [v0, v1] = tfRange();
      const u = (v - v0) / (v1 - v0 || 1);
      const lo = k > 0 ? own[k - 1][0] + 1e-4 : 0;
      const hi = k < own.length - 1 ? own[k + 1][0] - 1e-4 : 1;
      p[0] = Math.max(lo, Math.min(hi, u));
    }
    setHandles(own, map, k);
    syncPointColor();
    sendTF('full');
  };
  $('point-value').addEventListener('change', typed('point-value'));
  $('point-alpha').addEventListener('change', typed('point-alpha'));
  // A map: its stops join the opacity curve's handles (every point is one where no map is
  // followed yet). None: the handles stay, each with the colour the map gave it; the stops go.
  const maps = $('tf-colormap');
  maps.addEventListener('change', () => {
    if (!S.state) return;
    const pts = shown('data_tf').points;
    const { map, idx, hs, at: k } = handlePairs(pts);
    if (maps.value === (map || '')) return;
    const sel = Math.max(0, k);
    const ok = maps.value
      ? setHandles(hs, maps.value, sel)
      : setHandles(idx.map((i) => pts[i].slice()), null, sel);
    if (!ok) {
      maps.value = map || '';
      return;
    }
    syncPointColor();
    followDataTF(shown('data_tf').points); // time as lightness under a map's hue, unless time colours were chosen
    sendTF('full');
  });
  $('hist-log').addEventListener('change', drawTF);
  const remove = () => {
    const pts = shown('data_tf').points;
    const { map, hs, at: k } = handlePairs(pts);
    const own = map ? hs : pts.map((p) => p.slice());
    if (own.length <= 2 || k < 0) return;
    own.splice(k, 1);
    setHandles(own, map, Math.min(k, own.length - 1));
    syncPointColor();
    sendTF('full');
  };
  c.addEventListener('dblclick', remove);
  $('tf-delete').addEventListener('click', remove);
  $('point-color').addEventListener('input', () => {
    if (mapOf(shown('data_tf').points)) return; // the colours follow a map (the field is off)
    const p = shown('data_tf').points[S.selectedPoint];
    const hex = $('point-color').value;
    [1, 2, 3].forEach((j, k) => (p[j] = parseInt(hex.slice(1 + 2 * k, 3 + 2 * k), 16) / 255));
    sendTF('full');
  });
  c.addEventListener(
    'wheel',
    (e) => {
      e.preventDefault();
      const g = tfGeom();
      const u = g.U(at(e)[0]);
      const f = Math.exp(e.deltaY * 0.002);
      const [lo, hi] = S.zoom;
      let nlo = u - (u - lo) * f;
      let nhi = u + (hi - u) * f;
      if (nhi - nlo < 1e-3) return;
      setZoom(Math.max(0, nlo), Math.min(1, nhi));
    },
    { passive: false },
  );
  $('tf-reset-zoom').addEventListener('click', () => setZoom(0, 1));
  const fromInputs = () => {
    const [v0, v1] = series();
    const span = v1 - v0 || 1;
    const lo = (parseFloat($('zoom-lo').value) - v0) / span;
    const hi = (parseFloat($('zoom-hi').value) - v0) / span;
    if (Number.isFinite(lo) && Number.isFinite(hi) && hi - lo > 1e-4) setZoom(Math.max(0, lo), Math.min(1, hi));
    else drawTF();
  };
  $('zoom-lo').addEventListener('change', fromInputs);
  $('zoom-hi').addEventListener('change', fromInputs);
}

let histTimer = 0;
let histAsked = null;
function setZoom(lo, hi) {
  S.zoom = [lo, hi];
  histAsked = null; // asked again, counted anew
  drawTF();
  askHistogram(lo, hi);
}

// What a histogram over axis [lo, hi] counts for the selected view: the values, or a change
// mode's changes at the TF's value range. A histogram counted for another (a mode switched to
// or from change, a TF fitted anew) is asked for again when the editor is drawn.
function histKey(lo, hi, view = S.selectedView) {
  return changes() ? `${view} change ${lo} ${hi} ${values().join(' ')}` : `${view} value ${lo} ${hi}`;
}

function askHistogram(lo, hi) {
  const key = histKey(lo, hi);
  if (key === histAsked) return;
  histAsked = key;
  const msg = { type: 'histogram', range: [lo, hi], view: S.selectedView }; // its window
  if (changes()) Object.assign(msg, { of: 'change', value_range: shown('data_tf').value_range || null });
  clearTimeout(histTimer);
  histTimer = setTimeout(() => send(msg), 120);
}

// A histogram message, kept with what it counted (as `histKey` names it).
export function tookHistogram(msg) {
  const [lo, hi] = msg.range;
  const vr = msg.value_range || (S.info ? [S.info.vmin, S.info.vmax] : [0, 1]);
  const v = msg.view || 0;
  const key = msg.of === 'change' ? `${v} change ${lo} ${hi} ${vr.join(' ')}` : `${v} value ${lo} ${hi}`;
  S.histogram = { ...msg, key };
}
