// The timeline under the views: per-step sparklines of the data, the window brush (drag to
// select, move or resize it), stride, and play (speed in slides a second, loop or bounce).
// Its keys (arrows, space, +, -, b) are in keys.js's table. A thin bar under the step ticks
// shows which steps are in memory (the server's `steps` messages, residency.py): filled =
// resident, hatched = being fetched, empty = not loaded.

import { update } from './connection.js';
import { $, canvasSize } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindTimeline.
let S;
let viewer;

const tl = { drag: null };

export function drawTimeline() {
  if (!S.info) return;
  const [ctx, w, h] = canvasSize($('timeline'));
  const T = S.info.shape.t;
  const cell = w / T;
  const { t0, t1, stride } = S.state.window;
  ctx.clearRect(0, 0, w, h);
  const top = 14;
  const bottom = h - 14;
  const ph = bottom - top;
  const range = S.info.vmax - S.info.vmin || 1;
  const meanMax = Math.max(...S.info.step_mean.map((v) => v - S.info.vmin), 1e-12);
  // The window.
  ctx.fillStyle = 'rgba(240,160,48,0.16)';
  ctx.fillRect(t0 * cell, 0, (t1 - t0) * cell, h);
  // Sparklines: mean (filled, own scale) and max (line, over the value range).
  ctx.beginPath();
  ctx.moveTo(0, bottom);
  S.info.step_mean.forEach((v, s) => ctx.lineTo((s + 0.5) * cell, bottom - ((v - S.info.vmin) / meanMax) * ph));
  ctx.lineTo(w, bottom);
  ctx.closePath();
  ctx.fillStyle = 'rgba(120,160,210,0.35)';
  ctx.fill();
  ctx.beginPath();
  S.info.step_max.forEach((v, s) => {
    const y = bottom - ((v - S.info.vmin) / range) * ph;
    if (s === 0) ctx.moveTo((s + 0.5) * cell, y);
    else ctx.lineTo((s + 0.5) * cell, y);
  });
  ctx.strokeStyle = 'rgba(230,230,230,0.8)';
  ctx.lineWidth = 1.2;
  ctx.stroke();
  // Selected steps, coloured by their time colour.
  const colours = new Map(S.legend.map((l) => [l.step, l]));
  for (let s = t0; s < t1; s += stride) {
    const l = colours.get(s);
    ctx.fillStyle = l ? `rgb(${l.rgb.map((c) => Math.round(c * 255)).join(',')})` : '#f0a030';
    ctx.fillRect(s * cell + cell * 0.15, bottom + 2, Math.max(2, cell * 0.7), 5);
  }
  drawResidency(ctx, cell, bottom + 8, w);
  // Brush edges.
  ctx.strokeStyle = '#f0a030';
  ctx.lineWidth = 2;
  ctx.strokeRect(t0 * cell + 1, 1, (t1 - t0) * cell - 2, h - 2);
  // Axis labels.
  ctx.fillStyle = '#8b949e';
  ctx.font = '10px system-ui, sans-serif';
  ctx.textBaseline = 'bottom';
  const label = (s) => (S.info.time_labels ? S.info.time_labels[s] : String(s));
  ctx.fillText(label(0), 3, h - 1);
  ctx.textAlign = 'right';
  ctx.fillText(label(T - 1), w - 3, h - 1);
  ctx.textAlign = 'left';
  ctx.textBaseline = 'top';
  ctx.fillText('max ─  mean ▆', 3, 2);
  const last = t0 + Math.floor((t1 - 1 - t0) / stride) * stride;
  const span = S.info.time_labels ? `${label(t0)} .. ${label(last)}, ` : '';
  $('window-text').textContent = `${span}steps ${t0}:${t1}${stride > 1 ? ':' + stride : ''} (${Math.ceil((t1 - t0) / stride)} of ${T})`;
}

// Steps in memory over all views (each view's full-resolution window manager).
export function onSteps(msg) {
  const resident = new Set();
  const loading = new Set();
  for (const v of msg.views) {
    if (!v) continue;
    v.resident.forEach((s) => resident.add(s));
    v.loading.forEach((s) => loading.add(s));
  }
  resident.forEach((s) => loading.delete(s));
  S.residency = { resident, loading };
  viewer.residency = { resident: [...resident].sort((a, b) => a - b), loading: [...loading].sort((a, b) => a - b) };
  drawTimeline();
}

let hatch = null;
function hatchPattern(ctx) {
  if (!hatch) {
    const c = document.createElement('canvas');
    c.width = c.height = 6;
    const g = c.getContext('2d');
    g.fillStyle = 'rgba(88,166,255,0.25)';
    g.fillRect(0, 0, 6, 6);
    g.strokeStyle = 'rgba(88,166,255,0.95)';
    g.lineWidth = 1.5;
    g.beginPath();
    g.moveTo(-1, 7);
    g.lineTo(7, -1);
    g.stroke();
    hatch = c;
  }
  return ctx.createPattern(hatch, 'repeat');
}

function drawResidency(ctx, cell, y, w) {
  const r = S.residency;
  if (!r) return;
  const T = S.info.shape.t;
  const hgt = 4;
  ctx.strokeStyle = 'rgba(139,148,158,0.45)';
  ctx.lineWidth = 1;
  ctx.strokeRect(0.5, y - 0.5, w - 1, hgt + 1);
  const pattern = hatchPattern(ctx);
  for (let s = 0; s < T; s++) {
    const fill = r.resident.has(s) ? '#58a6ff' : r.loading.has(s) ? pattern : null;
    if (!fill) continue;
    ctx.fillStyle = fill;
    ctx.fillRect(s * cell + 0.5, y, Math.max(1, cell - 1), hgt);
  }
  // The key, top right: a swatch after each word.
  ctx.font = '10px system-ui, sans-serif';
  ctx.textBaseline = 'top';
  ctx.textAlign = 'right';
  let x = w - 3;
  for (const [label, fill] of [['fetching', pattern], ['in memory', '#58a6ff']]) {
    ctx.fillStyle = fill;
    ctx.fillRect(x - 8, 3, 8, 8);
    ctx.fillStyle = '#8b949e';
    ctx.fillText(label, x - 11, 2);
    x -= 14 + ctx.measureText(label).width + 8;
  }
  ctx.textAlign = 'left';
}

function setWindow(t0, t1, stride, quality = 'full') {
  const T = S.info.shape.t;
  t0 = Math.max(0, Math.min(T - 1, t0));
  t1 = Math.max(t0 + 1, Math.min(T, t1));
  const w = S.state.window;
  if (w.t0 === t0 && w.t1 === t1 && w.stride === stride) return false;
  update({ window: { t0, t1, stride } }, quality);
  drawTimeline();
  return true;
}

export function slide(k) {
  const { t0, t1, stride } = S.state.window;
  const T = S.info.shape.t;
  let shift = k * stride;
  shift = Math.max(-t0, Math.min(shift, T - t1));
  if (!shift) return false;
  return setWindow(t0 + shift, t1 + shift, stride);
}

export function bindTimeline(page) {
  ({ S, viewer } = page);
  // Page coordinates of a step on the timeline, for scripted use (the browser tests).
  viewer.timelineAt = (step) => {
    const r = $('timeline').getBoundingClientRect();
    return { x: r.left + ((step + 0.5) / S.info.shape.t) * r.width, y: r.top + r.height / 2 };
  };
  const c = $('timeline');
  const stepAt = (e) => {
    const r = c.getBoundingClientRect();
    return ((e.clientX - r.left) / r.width) * S.info.shape.t;
  };
  c.addEventListener('pointerdown', (e) => {
    if (!S.info) return;
    c.setPointerCapture(e.pointerId);
    const x = stepAt(e);
    const { t0, t1 } = S.state.window;
    const edge = (0.25 * S.info.shape.t * 8) / c.getBoundingClientRect().width; // 8 px in steps
    let kind = 'new';
    if (Math.abs(x - t0) < Math.max(edge, 0.25)) kind = 'left';
    else if (Math.abs(x - t1) < Math.max(edge, 0.25)) kind = 'right';
    else if (x > t0 && x < t1) kind = 'move';
    tl.drag = { kind, x0: x, t0, t1, anchor: Math.floor(x) };
  });
  c.addEventListener('pointermove', (e) => {
    if (!tl.drag) return;
    const x = stepAt(e);
    const d = tl.drag;
    const stride = S.state.window.stride;
    if (d.kind === 'move') {
      const T = S.info.shape.t;
      let shift = Math.round(x - d.x0);
      shift = Math.max(-d.t0, Math.min(shift, T - d.t1));
      setWindow(d.t0 + shift, d.t1 + shift, stride, 'preview');
    } else if (d.kind === 'left') {
      setWindow(Math.min(Math.round(x), d.t1 - 1), d.t1, stride, 'preview');
    } else if (d.kind === 'right') {
      setWindow(d.t0, Math.max(Math.round(x), d.t0 + 1), stride, 'preview');
    } else {
      const a = d.anchor;
      const b = Math.floor(x);
      setWindow(Math.min(a, b), Math.max(a, b) + 1, stride, 'preview');
    }
  });
  const end = () => {
    if (!tl.drag) return;
    tl.drag = null;
    update({}, 'full');
  };
  c.addEventListener('pointerup', end);
  c.addEventListener('pointercancel', end);
  $('stride').addEventListener('change', () => {
    const s = Math.max(1, Math.min(S.info.shape.t, parseInt($('stride').value, 10) || 1));
    $('stride').value = s;
    setWindow(S.state.window.t0, S.state.window.t1, s);
  });
  $('play').addEventListener('click', () => setPlaying(!S.playing));
  $('play-mode').addEventListener('change', () => setPlayMode($('play-mode').value));
  $('play-speed').addEventListener('change', () => setPlaySpeed(Number($('play-speed').value)));
}

// ------------------------------------------------------------------ play
// Play slides the window by one stride at `play.speed` slides a second (fewer when frames take
// longer: it waits for the frame of each slide before the next). At the end of the series
// 'loop' starts again from the beginning; 'bounce' turns back (and again at the start).
export const play = { speed: 10, mode: 'loop', dir: 1, last: 0 };
export const SPEED_RANGE = [0.5, 60];
let playTimer = 0;

export function setPlaying(on) {
  S.playing = on;
  $('play').textContent = on ? '❚❚' : '▶';
  clearTimeout(playTimer);
  if (on) {
    play.last = 0;
    tick();
  }
}

export function togglePlaying() {
  setPlaying(!S.playing);
}

export function setPlayMode(mode) {
  play.mode = mode === 'bounce' ? 'bounce' : 'loop';
  if (play.mode === 'loop') play.dir = 1;
  $('play-mode').value = play.mode;
}

export function setPlaySpeed(v) {
  const [lo, hi] = SPEED_RANGE;
  play.speed = Number.isFinite(v) ? Math.max(lo, Math.min(hi, v)) : play.speed;
  $('play-speed').value = play.speed;
}

// Faster or slower by a factor (the + and - keys).
export function scalePlaySpeed(f) {
  setPlaySpeed(+(play.speed * f).toPrecision(2));
}

function tick() {
  if (!S.playing || !S.info) return;
  const now = performance.now();
  const due = play.last + 1000 / play.speed;
  // Wait for the frame of the last slide, and for the slide's time to come.
  if ((viewer.last && viewer.last.id < viewer.sent) || now < due) {
    playTimer = setTimeout(tick, Math.max(5, Math.min(50, due - now)));
    return;
  }
  play.last = now;
  if (!slide(play.dir)) {
    if (play.mode === 'bounce') {
      play.dir = -play.dir;
      slide(play.dir);
    } else {
      const { t0, t1, stride } = S.state.window;
      setWindow(0, t1 - t0, stride);
    }
  }
  viewer.playLog.push({ at: now, t0: S.state.window.t0 });
  if (viewer.playLog.length > 200) viewer.playLog.shift();
  playTimer = setTimeout(tick, 1000 / play.speed);
}
