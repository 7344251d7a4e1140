// The on-view legend: in each view's foot band, the window's time colours as a bar of one cell
// per step (oldest left) with the steps' time labels (or numbers) under it, and the
// time-opacity curve over the bar, as the saved PNG's legend shows them. It comes from each
// frame's `legends` (S.legends: per view, its window's step, rgb, a). Beside it, where the
// data TF is coloured (a colour map), the data colour bar: the data TF's colours over the value
// range the view used, with ticks in data units (each frame's `colorbars`, from
// chronocl/render/colorbar.py). A view whose mode colours by the fraction of the window's steps
// (count: `Mode.legend` "fraction") gets its count bar there instead of the time legend, whose
// step colours mean nothing in it: the data TF's colours and opacity from no step to every step
// (each frame's `countbars`, from chronocl/viewer/frames.py), as the saved PNG draws it.
// `L` or **legend** in the header shows or hides them.

import { $ } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindLegend.
let S;
let viewer;

export const legendOn = { shown: true };

const PAD = 12; // the left pad holds the curve's α
const TOP = 5;
const CURVE_H = 22;
const BAR_H = 9;

// The smallest 1-2-5 step whose multiples in [lo, hi] number at most `most`.
function niceStep(lo, hi, most, integer) {
  const span = Math.abs(hi - lo);
  if (!span) return 1;
  const e0 = Math.floor(Math.log10(span / most));
  for (let e = e0 - 1; e < e0 + 3; e++) {
    for (const m of [1, 2, 5]) {
      const step = m * 10 ** e;
      if (integer && step < 1) continue;
      if (Math.floor(hi / step + 1e-9) - Math.ceil(lo / step - 1e-9) + 1 <= most) return step;
    }
  }
  return 10 ** (e0 + 3);
}

function draw(canvas, items) {
  canvas.hidden = !legendOn.shown || !items.length;
  if (canvas.hidden) return;
  const [ctx, w] = backdrop(canvas);
  const n = items.length;
  const x0 = PAD;
  const cell = (w - 2 * PAD) / n;
  const top = TOP;
  const barY = top + CURVE_H + 3;
  items.forEach((it, k) => {
    ctx.fillStyle = `rgb(${it.rgb.map((c) => Math.round(c * 255)).join(',')})`;
    ctx.fillRect(x0 + k * cell, barY, Math.max(1, cell - (n > 1 ? 1 : 0)), BAR_H);
  });
  // The time-opacity curve, a point per step over its cell, between faint lines at opacity 0
  // and 1; "α" names it.
  const X = (k) => x0 + (k + 0.5) * cell;
  const Y = (a) => top + 2 + (1 - a) * (CURVE_H - 4);
  ctx.strokeStyle = 'rgba(255,255,255,0.22)';
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (const a of [0, 1]) {
    ctx.moveTo(x0, Math.round(Y(a)) + 0.5);
    ctx.lineTo(w - PAD, Math.round(Y(a)) + 0.5);
  }
  ctx.stroke();
  ctx.beginPath();
  items.forEach((it, k) => (k ? ctx.lineTo(X(k), Y(it.a)) : ctx.moveTo(X(k), Y(it.a))));
  ctx.strokeStyle = '#f0a030';
  ctx.lineWidth = 1.6;
  ctx.stroke();
  ctx.fillStyle = '#f0a030';
  for (let k = 0; k < n && cell >= 6; k++) {
    ctx.beginPath();
    ctx.arc(X(k), Y(items[k].a), 1.8, 0, 2 * Math.PI);
    ctx.fill();
  }
  // Ticks at nice numbers (1, 2 or 5 times a power of ten) of the steps' numbers, or of their
  // times where every label is a number, placed where they fall between the steps' cells, as
  // many as fit (chronocl.core.ticks, as the saved PNG's legend); text and date labels: the
  // first and last, and between them as many as fit.
  ctx.fillStyle = '#e6e6e6';
  ctx.font = '10px system-ui, sans-serif';
  ctx.textBaseline = 'top';
  const names = S.info && S.info.time_labels;
  const label = (it) => (names && names[it.step] !== undefined ? names[it.step] : String(it.step));
  const numeric = items.map((it) => (names ? Number(names[it.step]) : it.step));
  const increasing = numeric.every((v, k) => Number.isFinite(v) && (k === 0 || v > numeric[k - 1]));
  const ticks = [];
  if (n > 1 && increasing && (!names || items.every((it) => String(names[it.step]).trim() !== ''))) {
    const integer = numeric.every(Number.isInteger);
    const widest = Math.max(...numeric.map((v) => ctx.measureText(String(v)).width));
    const most = Math.max(2, Math.floor((w - 2 * PAD) / (widest + 12)));
    const step = niceStep(numeric[0], numeric[n - 1], most, integer);
    const decimals = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
    const last = Math.floor(numeric[n - 1] / step + 1e-9);
    for (let j = Math.ceil(numeric[0] / step - 1e-9); j <= last; j++) {
      const t = j * step; // placed where it falls between the steps' cell centres
      let k = 1;
      while (k < n - 1 && numeric[k] < t) k++;
      const f = (t - numeric[k - 1]) / (numeric[k] - numeric[k - 1]);
      ticks.push({ text: t.toFixed(decimals), x: X(k - 1) + Math.max(0, Math.min(1, f)) * (X(k) - X(k - 1)) });
    }
    ctx.textAlign = 'center';
    ticks.forEach((t) => {
      const tw = ctx.measureText(t.text).width;
      ctx.fillText(t.text, Math.max(x0 + tw / 2, Math.min(w - PAD - tw / 2, t.x)), barY + BAR_H + 2);
    });
  } else {
    const widest = Math.max(...items.map((it) => ctx.measureText(label(it)).width));
    const every = Math.max(1, Math.ceil(n / Math.max(1, Math.floor((w - 2 * PAD) / (widest + 8)))));
    items.forEach((it, k) => {
      if (k % every && k !== n - 1) return;
      if (k !== n - 1 && n - 1 - k < every && k) return; // keep clear of the last label
      const end = k === 0 ? 'left' : k === n - 1 ? 'right' : 'center';
      ctx.textAlign = n > 1 && widest > cell ? end : 'center';
      const x = ctx.textAlign === 'left' ? x0 : ctx.textAlign === 'right' ? w - PAD : X(k);
      ctx.fillText(label(it), x, barY + BAR_H + 2);
      ticks.push({ text: label(it), x });
    });
  }
  canvas.dataset.ticks = ticks.map((t) => t.text).join(',');
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  ctx.fillStyle = '#9aa3ad';
  ctx.fillText('α', x0 - 1, Y(0.5));
  canvas.dataset.steps = items.map((it) => it.step).join(',');
  canvas.dataset.kind = 'time';
  delete canvas.dataset.bar;
}

// A canvas sized to its CSS box in device pixels, cleared, with the legends' dark backdrop.
function backdrop(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  ctx.fillStyle = 'rgba(16, 18, 21, 0.72)'; // readable on black and on white
  ctx.beginPath();
  ctx.roundRect(0, 0, w, h, 4);
  ctx.fill();
  return [ctx, w, h];
}

// The data colour bar `bar` ({title, range: [lo, hi], colors: ['#rrggbb', ...]}) or none: the
// title over its left end, the colours as a gradient ending level with the time bar, and
// ticks at nice numbers (1, 2 or 5 times a power of ten) of the value range in data units, as
// many as fit (as the saved PNG's colour bar: chronocl/render/legends.py).
function drawColourBar(canvas, bar) {
  canvas.hidden = !legendOn.shown || !bar;
  if (canvas.hidden) return;
  const [ctx, w] = backdrop(canvas);
  const x0 = PAD;
  const x1 = w - PAD;
  const bottom = TOP + CURVE_H + 3 + BAR_H; // level with the time bar's foot
  const y = TOP + 13;
  const grad = ctx.createLinearGradient(x0, 0, x1, 0);
  bar.colors.forEach((c, k) => grad.addColorStop(k / Math.max(1, bar.colors.length - 1), c));
  ctx.fillStyle = grad;
  ctx.fillRect(x0, y, x1 - x0, bottom - y);
  ctx.fillStyle = '#9aa3ad';
  ctx.font = '10px system-ui, sans-serif';
  ctx.textBaseline = 'top';
  ctx.textAlign = 'left';
  ctx.fillText(bar.title, x0, TOP - 1);
  const [lo, hi] = bar.range;
  const X = (v) => x0 + ((v - lo) / (hi - lo || 1)) * (x1 - x0);
  let most = Math.max(2, Math.floor((x1 - x0) / 16) + 1);
  let ticks;
  for (;;) {
    const step = niceStep(lo, hi, most, false);
    const decimals = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
    ticks = [];
    const last = Math.floor(hi / step + 1e-9);
    for (let j = Math.ceil(lo / step - 1e-9); j <= last; j++) {
      const text = (j * step).toFixed(decimals);
      ticks.push({ text: /^-?[0.]+$/.test(text) ? '0' : text, x: X(j * step) });
    }
    const widest = Math.max(0, ...ticks.map((t) => ctx.measureText(t.text).width));
    if (most <= 2 || ticks.length * (widest + 12) <= x1 - x0 + widest) break;
    most -= 1;
  }
  ctx.fillStyle = '#e6e6e6';
  ctx.strokeStyle = '#e6e6e6';
  ctx.textAlign = 'center';
  ticks.forEach((t) => {
    const tw = ctx.measureText(t.text).width;
    ctx.beginPath();
    ctx.moveTo(Math.round(t.x) + 0.5, bottom);
    ctx.lineTo(Math.round(t.x) + 0.5, bottom + 2);
    ctx.stroke();
    ctx.fillText(t.text, Math.max(tw / 2 + 1, Math.min(w - tw / 2 - 1, t.x)), bottom + 2);
  });
  // For scripted use (the tests): the ticks, the range and where the colours lie (CSS px).
  canvas.dataset.ticks = ticks.map((t) => t.text).join(',');
  canvas.dataset.range = `${lo},${hi}`;
  canvas.dataset.bar = `${x0},${x1},${(y + bottom) / 2}`;
}

// The count bar `bar` ({steps, ends: [none, all], colors, alpha}): what a count view's colour
// and opacity mean. The ends' names over the bar, the steps' number between them, the colours
// (weighted by opacity, as the saved PNG's) under the opacity curve α, and ticks at fractions
// of the steps that fit: quarters, halves or the ends.
function drawCountBar(canvas, bar) {
  canvas.hidden = !legendOn.shown;
  if (canvas.hidden) return;
  const [ctx, w] = backdrop(canvas);
  const x0 = PAD;
  const x1 = w - PAD;
  const barY = TOP + CURVE_H + 3;
  const n = bar.colors.length;
  const X = (f) => x0 + f * (x1 - x0);
  const grad = ctx.createLinearGradient(x0, 0, x1, 0);
  bar.colors.forEach((c, k) => grad.addColorStop(k / Math.max(1, n - 1), c));
  ctx.fillStyle = grad;
  ctx.fillRect(x0, barY, x1 - x0, BAR_H);
  const Y = (a) => TOP + 11 + (1 - a) * (CURVE_H - 13);
  ctx.beginPath();
  bar.alpha.forEach((a, k) => {
    const f = k / Math.max(1, bar.alpha.length - 1);
    if (k) ctx.lineTo(X(f), Y(a));
    else ctx.moveTo(X(f), Y(a));
  });
  ctx.strokeStyle = '#f0a030';
  ctx.lineWidth = 1.4;
  ctx.stroke();
  ctx.font = '10px system-ui, sans-serif';
  ctx.textBaseline = 'top';
  ctx.fillStyle = '#9aa3ad';
  ctx.textAlign = 'left';
  ctx.fillText(bar.ends[0], x0, TOP - 2);
  ctx.textAlign = 'right';
  ctx.fillText(bar.ends[1], x1, TOP - 2);
  ctx.textAlign = 'center';
  ctx.fillText(`of ${bar.steps} step${bar.steps === 1 ? '' : 's'}`, (x0 + x1) / 2, TOP - 2);
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  ctx.fillText('α', x0 - 1, Y(0.5));
  let fractions = [0, 1];
  for (const fs of [[0, 0.25, 0.5, 0.75, 1], [0, 0.5, 1]]) {
    if (ctx.measureText('100%').width + 6 <= (x1 - x0) / (fs.length - 1)) {
      fractions = fs;
      break;
    }
  }
  ctx.fillStyle = '#e6e6e6';
  ctx.textBaseline = 'top';
  ctx.textAlign = 'center';
  const ticks = fractions.map((f) => `${Math.round(100 * f)}%`);
  fractions.forEach((f, k) => {
    const tw = ctx.measureText(ticks[k]).width;
    const x = Math.max(x0 + tw / 2 - PAD / 2, Math.min(x1 - tw / 2 + PAD / 2, X(f)));
    ctx.fillText(ticks[k], x, barY + BAR_H + 2);
  });
  // For scripted use (the tests): what the legend shows, its ticks and where the bar lies.
  canvas.dataset.kind = 'fraction';
  canvas.dataset.ticks = ticks.join(',');
  canvas.dataset.steps = '';
  canvas.dataset.bar = `${x0},${x1},${barY + BAR_H / 2}`;
}

// Every view's legend (its time legend, or a count view's count bar) and data colour bar, for
// the frame shown.
export function drawLegends() {
  $('views').querySelectorAll('.view').forEach((view, i) => {
    const legend = view.querySelector('canvas.legend');
    const count = S.countbars && S.countbars[i];
    if (count) drawCountBar(legend, count);
    else draw(legend, (S.legends && S.legends[i]) || S.legend || []);
    const bar = view.querySelector('canvas.colorbar');
    if (bar) drawColourBar(bar, S.colorbars ? S.colorbars[i] : null);
  });
}

export function toggleLegend(on = !legendOn.shown) {
  legendOn.shown = on;
  $('legend-on').checked = on;
  drawLegends();
}

export function bindLegend(page) {
  ({ S, viewer } = page);
  // Where step k's colour cell is in a legend canvas (CSS px), for scripted use (the tests).
  viewer.legendCell = (k) => {
    const c = $('views').querySelector('.view canvas.legend');
    const cell = (c.clientWidth - 2 * PAD) / S.legend.length;
    return { x: PAD + (k + 0.5) * cell, y: TOP + CURVE_H + 3 + BAR_H / 2 };
  };
  $('legend-on').addEventListener('change', () => toggleLegend($('legend-on').checked));
}
