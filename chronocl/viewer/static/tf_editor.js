// The data transfer function editor: a histogram of the window's values (log or linear) under
// the opacity curve and its colour strip; drag points, click to add, double-click to remove,
// wheel to zoom in u; the selected point's value and opacity typed in; a readout of value,
// opacity and count under the pointer; colour-map presets (the server's stops,
// chronocl/core/colormaps.py, applied as `DataTF.with_colormap` does: opacity kept).

import { send, update } from './connection.js';
import { $, S, canvasSize, fmt, viewer } from './state.js';

const tf = { drag: null };
const pad = { l: 6, r: 6, t: 8, b: 18 };
function tfGeom() {
  const [ctx, w, h] = canvasSize($('tf'));
  const [lo, hi] = S.zoom;
  const X = (u) => pad.l + ((u - lo) / (hi - lo)) * (w - pad.l - pad.r);
  const U = (x) => lo + ((x - pad.l) / (w - pad.l - pad.r)) * (hi - lo);
  const Y = (a) => h - pad.b - a * (h - pad.t - pad.b);
  const A = (y) => (h - pad.b - y) / (h - pad.t - pad.b);
  return { ctx, w, h, X, U, Y, A };
}
const rgbCss = (p, a = 1) => `rgba(${Math.round(p[1] * 255)},${Math.round(p[2] * 255)},${Math.round(p[3] * 255)},${a})`;
const dataValue = (u) => S.info.vmin + u * (S.info.vmax - S.info.vmin);

export function drawTF() {
  if (!S.state) return;
  const { ctx, w, h, X, Y } = tfGeom();
  const pts = S.state.data_tf.points;
  ctx.clearRect(0, 0, w, h);
  const hist = S.histogram;
  if (hist && hist.range[0] === S.zoom[0] && hist.range[1] === S.zoom[1]) {
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
  const grad = ctx.createLinearGradient(X(pts[0][0]), 0, X(pts[pts.length - 1][0]), 0);
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
  ctx.beginPath();
  ctx.moveTo(X(Math.min(S.zoom[0], pts[0][0])), Y(pts[0][4]));
  for (const p of pts) ctx.lineTo(X(p[0]), Y(p[4]));
  ctx.lineTo(X(Math.max(S.zoom[1], pts[pts.length - 1][0])), Y(pts[pts.length - 1][4]));
  ctx.strokeStyle = '#f0a030';
  ctx.lineWidth = 1.5;
  ctx.stroke();
  ctx.restore();
  const zspan = S.zoom[1] - S.zoom[0];
  pts.forEach((p, i) => {
    if (p[0] < S.zoom[0] - 1e-3 * zspan || p[0] > S.zoom[1] + 1e-3 * zspan) return;
    ctx.beginPath();
    ctx.arc(X(p[0]), Y(p[4]), i === S.selectedPoint ? 6 : 4.5, 0, 2 * Math.PI);
    ctx.fillStyle = rgbCss(p);
    ctx.fill();
    ctx.lineWidth = i === S.selectedPoint ? 2.5 : 1.2;
    ctx.strokeStyle = i === S.selectedPoint ? '#f0a030' : '#222';
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
}

function sendTF(quality) {
  update({ data_tf: { points: S.state.data_tf.points.map((p) => p.slice()) } }, quality);
  drawTF();
}

// The selected point's colour, value and opacity into their fields.
export function syncPointColor() {
  const p = S.state.data_tf.points[S.selectedPoint];
  if (!p) return;
  const hex = (v) => Math.round(v * 255).toString(16).padStart(2, '0');
  $('point-color').value = `#${hex(p[1])}${hex(p[2])}${hex(p[3])}`;
  if (S.info) $('point-value').value = fmt(dataValue(p[0]));
  $('point-alpha').value = fmt(p[4]);
}

// Piecewise-linear value of column j of sorted points [x, ...] at x (constant beyond the ends).
function interp(pts, x, j) {
  if (x <= pts[0][0]) return pts[0][j];
  for (let k = 1; k < pts.length; k++) {
    if (x <= pts[k][0]) {
      const [a, b] = [pts[k - 1], pts[k]];
      return b[0] === a[0] ? b[j] : a[j] + ((x - a[0]) / (b[0] - a[0])) * (b[j] - a[j]);
    }
  }
  return pts[pts.length - 1][j];
}

// The points recoloured by colour map `name`: the map's stops and the existing positions, each
// with the map's colour and the opacity the curve has there.
function withColormap(pts, name) {
  const stops = S.choices.colormaps[name];
  const us = [...new Set([...pts.map((p) => p[0]), ...stops.map((s) => s[0])])].sort((a, b) => a - b);
  return us
    .filter((u, k) => k === 0 || u - us[k - 1] > 1e-9)
    .map((u) => [u, interp(stops, u, 1), interp(stops, u, 2), interp(stops, u, 3), interp(pts, u, 4)]);
}

function showHover(u) {
  const out = $('tf-hover');
  if (u === null || !S.info) {
    out.innerHTML = '&nbsp;';
    return;
  }
  const pts = S.state.data_tf.points;
  let text = `value ${fmt(dataValue(u))} · opacity ${fmt(interp(pts, u, 4))}`;
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
  $('tf-colormap').replaceChildren(new Option('choose…', ''), ...names.map((n) => new Option(n, n)));
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
  $('hist-note').textContent = `histogram of ${which}; opacity up, value across`;
}

export function bindTF() {
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
    const pts = S.state.data_tf.points;
    let best = -1;
    let bestD = 9;
    pts.forEach((p, i) => {
      const d = Math.hypot(g.X(p[0]) - x, g.Y(p[4]) - y);
      if (d < bestD) [best, bestD] = [i, d];
    });
    if (best < 0) {
      // A new point on the curve's colour at that value.
      const u = clamp01(g.U(x));
      if (pts.some((p) => Math.abs(p[0] - u) < 1e-4) || pts.length >= S.choices.limits.max_tf_points) return;
      let k = pts.findIndex((p) => p[0] > u);
      if (k < 0) k = pts.length;
      const rgb = [1, 2, 3].map((j) => interp(pts, u, j));
      pts.splice(k, 0, [u, ...rgb, clamp01(g.A(y))]);
      best = k;
    }
    S.selectedPoint = best;
    syncPointColor();
    c.setPointerCapture(e.pointerId);
    tf.drag = { i: best };
    sendTF('preview');
  });
  c.addEventListener('pointermove', (e) => {
    if (!tf.drag) {
      if (S.state) showHover(clamp01(tfGeom().U(at(e)[0])));
      return;
    }
    const g = tfGeom();
    const [x, y] = at(e);
    const pts = S.state.data_tf.points;
    const i = tf.drag.i;
    const lo = i > 0 ? pts[i - 1][0] + 1e-4 : 0;
    const hi = i < pts.length - 1 ? pts[i + 1][0] - 1e-4 : 1;
    pts[i][0] = Math.max(lo, Math.min(hi, clamp01(g.U(x))));
    pts[i][4] = clamp01(g.A(y));
    syncPointColor(); // the value and opacity fields follow the point as it moves
    showHover(pts[i][0]);
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
    const pts = S.state.data_tf.points;
    const i = S.selectedPoint;
    const p = pts[i];
    const v = parseFloat($(field).value);
    if (!p || !S.info || !Number.isFinite(v)) return syncPointColor();
    if (field === 'point-alpha') p[4] = clamp01(v);
    else {
      const u = (v - S.info.vmin) / (S.info.vmax - S.info.vmin || 1);
      const lo = i > 0 ? pts[i - 1][0] + 1e-4 : 0;
      const hi = i < pts.length - 1 ? pts[i + 1][0] - 1e-4 : 1;
      p[0] = Math.max(lo, Math.min(hi, u));
    }
    syncPointColor();
    sendTF('full');
  };
  $('point-value').addEventListener('change', typed('point-value'));
  $('point-alpha').addEventListener('change', typed('point-alpha'));
  const maps = $('tf-colormap');
  maps.addEventListener('change', () => {
    if (!maps.value || !S.state) return;
    const pts = withColormap(S.state.data_tf.points, maps.value);
    maps.value = '';
    if (pts.length > S.choices.limits.max_tf_points) {
      $('tf-hover').textContent = `a colour map needs ${pts.length} points; remove some (at most ${S.choices.limits.max_tf_points})`;
      return;
    }
    S.state.data_tf.points = pts;
    S.selectedPoint = Math.min(S.selectedPoint, pts.length - 1);
    syncPointColor();
    sendTF('full');
  });
  $('hist-log').addEventListener('change', drawTF);
  const remove = () => {
    const pts = S.state.data_tf.points;
    if (pts.length <= 2) return;
    pts.splice(S.selectedPoint, 1);
    S.selectedPoint = Math.min(S.selectedPoint, pts.length - 1);
    syncPointColor();
    sendTF('full');
  };
  c.addEventListener('dblclick', remove);
  $('tf-delete').addEventListener('click', remove);
  $('point-color').addEventListener('input', () => {
    const p = S.state.data_tf.points[S.selectedPoint];
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
    const span = S.info.vmax - S.info.vmin || 1;
    const lo = (parseFloat($('zoom-lo').value) - S.info.vmin) / span;
    const hi = (parseFloat($('zoom-hi').value) - S.info.vmin) / span;
    if (Number.isFinite(lo) && Number.isFinite(hi) && hi - lo > 1e-4) setZoom(Math.max(0, lo), Math.min(1, hi));
    else drawTF();
  };
  $('zoom-lo').addEventListener('change', fromInputs);
  $('zoom-hi').addEventListener('change', fromInputs);
}

let histTimer = 0;
function setZoom(lo, hi) {
  S.zoom = [lo, hi];
  drawTF();
  clearTimeout(histTimer);
  histTimer = setTimeout(() => send({ type: 'histogram', range: [lo, hi] }), 120);
}

// Page coordinates of a TF point's handle, for scripted use (the browser tests).
viewer.tfPointAt = (i) => {
  const g = tfGeom();
  const r = $('tf').getBoundingClientRect();
  const p = S.state.data_tf.points[i];
  return { x: r.left + g.X(p[0]), y: r.top + g.Y(p[4]) };
};
