// A small plot of values over the series' steps, the window's steps marked on it: the probe's
// v(t) (probe.js) and the events panel's size and value of a track (events.js) are drawn by it.
// x spans the steps 0..T-1 (the series' first and last time labels under it), y `lo`..`hi`
// (their values at the left); the window's span is shaded and its steps dotted on the curve.

import { canvasSize, fmt } from './state.js';

// Draws on canvas `c`: `values` (one per step, null where there is none: the line breaks
// there), an optional `min`/`max` band, the window's `steps` (a list), in `colour`, with an
// optional `title` above it. Returns whether anything was drawn.
export function drawTimePlot(c, { T, lo, hi, values, min, max, steps, labels, colour = '#7fb8ff', title }) {
  const [ctx, w, h] = canvasSize(c);
  ctx.clearRect(0, 0, w, h);
  if (!values || !T || !steps || !steps.length) return false;
  if (!(hi > lo)) hi = lo + 1;
  const p = { l: 40, r: 6, t: title ? 15 : 8, b: 16 };
  const X = (s) => p.l + (T > 1 ? s / (T - 1) : 0.5) * (w - p.l - p.r);
  const Y = (v) => h - p.b - ((v - lo) / (hi - lo)) * (h - p.t - p.b);
  ctx.fillStyle = 'rgba(240,160,48,0.16)';
  ctx.fillRect(X(steps[0]) - 2, p.t, X(steps[steps.length - 1]) - X(steps[0]) + 4, h - p.t - p.b);
  ctx.strokeStyle = '#343941';
  ctx.lineWidth = 1;
  ctx.strokeRect(p.l, p.t, w - p.l - p.r, h - p.t - p.b);
  if (min && max) {
    ctx.beginPath();
    max.forEach((v, s) => (s === 0 ? ctx.moveTo(X(s), Y(v)) : ctx.lineTo(X(s), Y(v))));
    for (let s = T - 1; s >= 0; s--) ctx.lineTo(X(s), Y(min[s]));
    ctx.closePath();
    ctx.fillStyle = 'rgba(127,184,255,0.22)';
    ctx.fill();
  }
  ctx.beginPath();
  let pen = false;
  values.forEach((v, s) => {
    if (v === null || v === undefined) {
      pen = false;
      return;
    }
    if (pen) ctx.lineTo(X(s), Y(v));
    else ctx.moveTo(X(s), Y(v));
    pen = true;
  });
  ctx.strokeStyle = colour;
  ctx.lineWidth = 1.6;
  ctx.stroke();
  ctx.fillStyle = '#f0a030';
  for (const s of steps) {
    const v = values[s];
    if (v === null || v === undefined) continue;
    ctx.beginPath();
    ctx.arc(X(s), Y(v), 2.6, 0, 2 * Math.PI);
    ctx.fill();
  }
  ctx.fillStyle = '#8b949e';
  ctx.font = '10px system-ui, sans-serif';
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  ctx.fillText(String(fmt(hi)), p.l - 3, p.t + 3);
  ctx.fillText(String(fmt(lo)), p.l - 3, h - p.b - 2);
  ctx.textBaseline = 'bottom';
  ctx.textAlign = 'left';
  ctx.fillText(labels ? labels[0] : 't = 0', p.l, h);
  ctx.textAlign = 'right';
  ctx.fillText(labels ? labels[T - 1] : String(T - 1), w - p.r, h);
  if (title) { // in the band above the plot
    ctx.textAlign = 'left';
    ctx.textBaseline = 'top';
    ctx.fillStyle = colour;
    ctx.fillText(title, p.l, 2);
  }
  c.dataset.drawn = String(Number(c.dataset.drawn || 0) + 1);
  return true;
}

// The window's steps (t0, t0 + stride, ... below t1 and T).
export function windowSteps({ t0, t1, stride }, T) {
  const out = [];
  for (let s = t0; s < Math.min(t1, T); s += stride) out.push(s);
  return out;
}
