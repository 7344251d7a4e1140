// The timeline under the views: per-step sparklines of the data, the window brush (drag to
// select, move or resize it), stride, and play (speed in slides a second, loop or bounce).
// Its keys (arrows, space, +, -, b) are in keys.js's table. Under the sparklines the steps each
// view integrates in their time colours: one row of cells where every view draws the same
// (linked), else a row per view that draws its own (its own window or time TF; views drawing
// alike share a row), top to bottom in the views' order, the selected view's row bright and the
// others faded, as a track per layer; the canvas' tooltip names each row's views and window.
// A thin bar under them shows which steps are in memory (the server's `steps` messages,
// residency.py): filled = resident, hatched = being fetched, empty = not loaded. Under it, in
// a row of their own, the axis' ticks at nice steps or times (ticks.js), as many as fit apart.

import { update } from './connection.js';
import { $, canvasSize } from './state.js';
import { axisOf, axisTicks } from './ticks.js';

// The page's state (state.js: pageState), made by app.js and given to bindTimeline.
let S;
let viewer;

const tl = { drag: null, title: '' }; // title: the canvas' own tooltip (index.html)

// The canvas from the top: a key row (the sparklines' key left, the residency key right), the
// sparklines, the views' steps in their time colours (a row or more), the residency bar, and
// the axis: tick marks and labels in a row of their own that nothing else draws into (ticks.js
// places them).
const KEY_H = 14; // the key row
const AXIS_H = 13; // tick marks and labels
const RES_H = 4; // the residency bar
const CELL_H = 5; // a row of time-colour cells, the tallest
const CELLS_H = 15; // the most that the rows take together (four of 3 px, 1 px apart)

// The rows of time-colour cells: each view's steps (its own window's, else the timeline's,
// as the state says now, so they follow a drag before its frame comes) coloured as its last
// frame's legend colours them; views whose cells are alike share a row. [{views, steps, rgb}]
function cellRows() {
  const rows = [];
  S.state.views.forEach((view, v) => {
    const { t0, t1, stride } = view.window || S.state.window;
    const legend = (S.legends && S.legends[v]) || S.legend;
    const colours = new Map(legend.map((l) => [l.step, l.rgb]));
    const steps = [];
    for (let s = t0; s < t1; s += stride) steps.push(s);
    const rgb = steps.map((s) => colours.get(s) || null);
    const key = JSON.stringify([steps, rgb]);
    const row = rows.find((r) => r.key === key);
    if (row) row.views.push(v);
    else rows.push({ key, views: [v], steps, rgb, window: view.window });
  });
  return rows;
}

// 'view 1' or 'views 2, 3', and what their row shows (for the tooltip).
function rowText(r) {
  const who = `view${r.views.length > 1 ? 's' : ''} ${r.views.map((v) => v + 1).join(', ')}`;
  const { t0, t1, stride } = r.window || S.state.window;
  const own = r.window ? 'own window ' : 'steps ';
  const tf = r.views.some((v) => S.state.views[v].time_tf) ? ', own time TF' : '';
  return `${who}: ${own}${t0}:${t1}${stride > 1 ? ':' + stride : ''}${tf}`;
}

export function drawTimeline() {
  if (!S.info) return;
  const c = $('timeline');
  const [ctx, w, h] = canvasSize(c);
  const T = S.info.shape.t;
  const cell = w / T;
  const { t0, t1, stride } = S.state.window;
  ctx.clearRect(0, 0, w, h);
  const axisTop = h - AXIS_H; // labels and marks below it, nothing else
  const resY = axisTop - 1 - RES_H; // the residency bar (its frame half a px around)
  const rows = cellRows();
  const rowH = Math.max(3, Math.min(CELL_H, Math.floor((CELLS_H + 1) / rows.length) - 1));
  const cellY = resY - 2 - rows.length * (rowH + 1) + 1; // the top row's
  const top = KEY_H;
  const bottom = cellY - 2; // the sparklines' foot
  const ph = bottom - top;
  const range = S.info.vmax - S.info.vmin || 1;
  const meanMax = Math.max(...S.info.step_mean.map((v) => v - S.info.vmin), 1e-12);
  // The window, over everything but the axis row.
  ctx.fillStyle = 'rgba(240,160,48,0.16)';
  ctx.fillRect(t0 * cell, 0, (t1 - t0) * cell, axisTop);
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
  // The views' steps, coloured by their time colour (orange before a frame says it).
  const cells = [];
  const selected = rows.length > 1 ? rows.findIndex((r) => r.views.includes(S.selectedView)) : 0;
  const rowBoxes = rows.map((r, k) => {
    const y = cellY + k * (rowH + 1);
    ctx.globalAlpha = k === selected ? 1 : 0.45;
    r.steps.forEach((s, j) => {
      const rgb = r.rgb[j];
      ctx.fillStyle = rgb ? `rgb(${rgb.map((c) => Math.round(c * 255)).join(',')})` : '#f0a030';
      const box = { x: s * cell + cell * 0.15, y, w: Math.max(2, cell * 0.7), h: rowH };
      ctx.fillRect(box.x, box.y, box.w, box.h);
      cells.push(box);
    });
    return { views: r.views, steps: r.steps, y, h: rowH, selected: k === selected };
  });
  ctx.globalAlpha = 1;
  const which = rows.length > 1 ? `\ncells, top to bottom:\n${rows.map(rowText).join('\n')}` : '';
  c.title = tl.title + which;
  drawResidency(ctx, cell, resY, w);
  // Brush edges, down to the axis row.
  ctx.strokeStyle = '#f0a030';
  ctx.lineWidth = 2;
  ctx.strokeRect(t0 * cell + 1, 1, (t1 - t0) * cell - 2, axisTop - 2);
  // The axis: a mark and a label at each tick, in the row under the cells and the residency bar.
  ctx.font = '10px system-ui, sans-serif';
  const axis = axisOf(S.info);
  const ticks = axisTicks(axis, w, (t) => ctx.measureText(t).width, (s) => (s + 0.5) * cell);
  ctx.strokeStyle = 'rgba(139,148,158,0.8)';
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (const t of ticks) {
    ctx.moveTo(Math.round(t.x) + 0.5, axisTop);
    ctx.lineTo(Math.round(t.x) + 0.5, axisTop + 2);
  }
  ctx.stroke();
  ctx.fillStyle = '#8b949e';
  ctx.textAlign = 'left';
  ctx.textBaseline = 'alphabetic';
  const base = h - 3;
  const labels = ticks.map((t) => {
    const m = ctx.measureText(t.text);
    ctx.fillText(t.text, t.left, base);
    return {
      text: t.text, x: t.left, w: t.right - t.left,
      y: base - m.actualBoundingBoxAscent, h: m.actualBoundingBoxAscent + m.actualBoundingBoxDescent,
    };
  });
  ctx.textBaseline = 'top';
  ctx.fillText('max ─  mean ▆', 3, 2);
  // For scripted use (the tests): what is drawn where, in CSS px of the canvas.
  c.dataset.ticks = ticks.map((t) => t.text).join('|');
  viewer.timelineLayout = {
    width: w, height: h, axis: axis.kind, axisTop, labels, cells, rows: rowBoxes,
    residency: { x: 0, y: resY - 0.5, w, h: RES_H + 1 },
  };
  const label = (s) => (S.info.time_labels ? S.info.time_labels[s] : String(s));
  const last = t0 + Math.floor((t1 - 1 - t0) / stride) * stride;
  const span = S.info.time_labels ? `${spanText(label(t0), label(last))}, ` : '';
  // (no break inside 'steps t0:t1' or '(n of T)' where the text wraps)
  $('window-text').textContent = `${span}steps\u00a0${t0}:${t1}${stride > 1 ? ':' + stride : ''} (${Math.ceil((t1 - t0) / stride)}\u00a0of\u00a0${T})`;
}

// 'first .. last' of two time labels, the last without the date the two share
// ('2024-01-01 06:00 .. 18:00'), as chronocl/core/time_labels.py's span_text.
function spanText(first, last) {
  if (first === last) return first;
  const [dateA, timeA] = first.split(' ');
  const [dateB, timeB] = last.split(' ');
  const same = timeA && timeB && dateA === dateB && /^\d{4}-\d{2}-\d{2}$/.test(dateA);
  return `${first} .. ${same ? timeB : last}`;
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
  tl.title = c.title;
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
