// The view panels: their grid, each panel's mode menu and order button, its links (its
// camera, data TF and time TF: the shared ones, or its own), orbit and zoom by pointer, the
// probe click and its marker, and the frames the server sends into them.
//
// A link toggled off gives the view its own copy of the shared one (unlinked) and selects the
// view: the TF editors, the time TF controls and the camera's buttons then edit its copy, and a
// drag on its picture turns its own camera; toggled on again, the copy is dropped (linked).

import { showAxes } from './box_axes.js';
import { LINKABLE, frameArrived, send, sentAt, settleLater, shown, update } from './connection.js';
import { modeChanged } from './fit.js';
import { drawLegends } from './legend.js';
import { drawTriads, turnedNormal } from './orientation.js';
import { drawProbe } from './probe.js';
import { $, clamp, setStatus } from './state.js';
import { noteRange } from './tf_editor.js';
import { drawTimeline } from './timeline.js';

// The page's state (state.js: pageState), made by app.js and given to bindViews.
let S;
let viewer;
let shell; // the element holding the viewer (state.js: pageState)
let onSelect = () => {}; // a view selected: the side panel's editors show what it is drawn with

// Each link's toggle: its label, and what it links.
const LINKS = { camera: ['cam', 'camera'], data_tf: ['TF', 'data TF'], time_tf: ['time', 'time TF'] };

const GAP = 6; // between panels and around them (the #views padding), CSS px
const panels = [];

// One option per item: a name, or {name, label, summary}.
export function fillSelect(el, items) {
  el.replaceChildren(
    ...items.map((item) => {
      const o = document.createElement('option');
      const it = typeof item === 'object' ? item : { name: String(item) };
      o.value = it.name;
      o.textContent = it.label || it.name;
      if (it.summary) o.title = it.summary;
      return o;
    }),
  );
}

export function layoutViews() {
  const n = S.state.views.length;
  const box = $('views');
  const { min_panel: minPanel, max_panel: maxPanel } = S.choices.limits;
  while (panels.length > n) {
    const p = panels.pop();
    if (pictureObserver) pictureObserver.unobserve(p.pic);
    p.el.remove();
  }
  while (panels.length < n) panels.push(makePanel(panels.length));
  panels.forEach((p, i) => {
    p.mode.value = S.state.views[i].mode;
    p.mode.title = S.choices.modes.find((m) => m.name === p.mode.value)?.summary || '';
    p.order.textContent = S.state.views[i].order || S.choices.orders[0];
    // not under the user's typing: a relayout (a legend appearing) would undo a window half
    // typed, and its Enter would then send nothing
    if (p.own.getRootNode().activeElement !== p.own) {
      p.own.value = windowText(S.state.views[i].window);
      p.own.classList.remove('bad');
    }
    p.el.classList.toggle('selected', i === S.selectedView && n > 1);
    showLinks(p, S.state.views[i]);
  });
  // Panels fill the view area in a grid (columns x rows): the squarest grid with room for n
  // (2x2 for four views) unless another gives pictures with a clearly (25 %) longer short
  // side, as a row of two on a wide area or a column of two on a tall one. A panel is its
  // picture between two bands (controls and caption above, legend and axes below), so the
  // picture is the cell less the bands' height.
  const W = box.clientWidth - 2 * GAP;
  const H = box.clientHeight - 2 * GAP;
  const bands = panels[0].head.offsetHeight + panels[0].foot.offsetHeight + 2; // + border
  const cell = (c) => {
    const r = Math.ceil(n / c);
    return { c, r, w: (W - GAP * (c - 1)) / c - 2, h: (H - GAP * (r - 1)) / r - bands };
  };
  let best = cell(Math.ceil(Math.sqrt(n)));
  for (let c = 1; c <= n; c++) {
    const g = cell(c);
    if (Math.min(g.w, g.h) > 1.25 * Math.min(best.w, best.h)) best = g;
  }
  S.columns = best.c;
  box.style.gridTemplateColumns = `repeat(${best.c}, minmax(0, 1fr))`;
  box.style.gridTemplateRows = `repeat(${best.r}, minmax(0, 1fr))`;
  // Render size: the picture's box (measured, now the grid is set) in device pixels, the
  // longest side within the server's limit (the server draws fewer pixels still when the
  // views together exceed its budget).
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, panels[0].pic.clientWidth) * dpr;
  const h = Math.max(1, panels[0].pic.clientHeight) * dpr;
  const fit = Math.min(1, maxPanel / Math.max(w, h));
  return [Math.max(minPanel, Math.round(w * fit)), Math.max(minPanel, Math.round(h * fit))];
}

// The page's state, `cb` for pictures that change size (the window, the side panel, the
// legend or axes shown or hidden; app.js: a new layout and render size), and `selected` for a
// view selected (app.js: the editors drawn again for it).
let pictureObserver = null;
export function bindViews(page, cb, selected = () => {}) {
  ({ S, viewer, shell } = page);
  onSelect = selected;
  pictureObserver = new ResizeObserver(cb);
  for (const p of panels) pictureObserver.observe(p.pic);
}

function makePanel(i) {
  const el = document.createElement('div');
  el.className = 'view';
  el.dataset.i = i;
  // Above the picture its controls and caption, below it the legend and the axes: no text
  // over the picture but the note of a (nearly) empty one.
  el.innerHTML =
    '<div class="view-head">' +
    '<select class="mode" title="Integration mode"></select>' +
    '<button class="order" title="Integration order (which steps are in front)"></button>' +
    '<input class="own-window" placeholder="linked" size="8" spellcheck="false" ' +
    'title="This view\'s own window t0:t1[:stride], to compare two periods side by side; ' +
    'empty: the timeline\'s window">' +
    '<span class="links">' +
    LINKABLE.map((k) => `<button class="link" data-link="${k}">${LINKS[k][0]}</button>`).join('') +
    '</span>' +
    '<div class="view-label"></div></div>' +
    '<div class="view-pic"><img alt="view" draggable="false">' +
    '<svg class="clip-outline" viewBox="0 0 1 1" preserveAspectRatio="none"><polygon class="clip-cut"/>' +
    '<polygon class="slice-cut"/></svg><svg class="box-axes"></svg>' +
    '<div class="probe-mark"></div><div class="probe-band"></div>' +
    '<div class="view-note" hidden></div></div>' +
    '<div class="view-foot"><canvas class="legend"></canvas><canvas class="colorbar" hidden></canvas>' +
    '<canvas class="triad"></canvas></div>';
  $('views').appendChild(el);
  const p = {
    el,
    head: el.querySelector('.view-head'),
    pic: el.querySelector('.view-pic'),
    foot: el.querySelector('.view-foot'),
    img: el.querySelector('img'),
    mode: el.querySelector('.mode'),
    order: el.querySelector('.order'),
    own: el.querySelector('.own-window'),
    links: el.querySelector('.links'),
    label: el.querySelector('.view-label'),
    note: el.querySelector('.view-note'),
    mark: el.querySelector('.probe-mark'),
    band: el.querySelector('.probe-band'),
    outline: el.querySelector('.clip-outline .clip-cut'),
    sliceCut: el.querySelector('.clip-outline .slice-cut'),
    axes: el.querySelector('.box-axes'),
    triad: el.querySelector('.triad'),
  };
  if (pictureObserver) pictureObserver.observe(p.pic);
  fillSelect(p.mode, S.choices.modes);
  p.mode.addEventListener('change', () => {
    const views = S.state.views.map((v) => ({ ...v }));
    views[i].mode = p.mode.value;
    p.mode.title = S.choices.modes.find((m) => m.name === p.mode.value)?.summary || '';
    modeChanged(i, views); // the default curve fitted again to the first view's mode
  });
  p.order.addEventListener('click', () => {
    const orders = S.choices.orders;
    const views = S.state.views.map((v) => ({ ...v }));
    const k = orders.indexOf(views[i].order || orders[0]);
    views[i].order = orders[(k + 1) % orders.length];
    p.order.textContent = views[i].order;
    update({ views });
  });
  p.own.addEventListener('change', () => {
    const text = p.own.value.trim();
    const window = text ? parseWindow(text) : null;
    p.own.classList.toggle('bad', window === undefined);
    if (window === undefined) return;
    const views = S.state.views.map((v) => ({ ...v }));
    views[i].window = window;
    update({ views });
  });
  for (const b of p.links.querySelectorAll('.link')) {
    b.addEventListener('click', () => toggleLink(i, b.dataset.link));
  }
  bindOrbit(p, i);
  return p;
}

// A view's links as its toggles show them: pressed (orange) where it has its own. They show
// where there are views to set apart, or where a view has its own.
function showLinks(p, view) {
  for (const b of p.links.querySelectorAll('.link')) {
    const key = b.dataset.link;
    const own = !!view[key];
    const what = LINKS[key][1];
    b.classList.toggle('own', own);
    b.setAttribute('aria-pressed', String(own));
    b.title = own
      ? `this view's own ${what} (selected, the editors edit it); click: linked to the shared ${what} again`
      : `linked: the shared ${what}; click: this view's own ${what}, to set it apart`;
  }
  p.links.hidden = S.state.views.length < 2 && !LINKABLE.some((k) => view[k]);
}

// View `i` linked to the shared `key` again (its own dropped), or given its own copy of it
// (and selected, so that the editors edit that copy).
export function toggleLink(i, key) {
  const views = S.state.views.map((v) => ({ ...v }));
  const own = !views[i][key];
  views[i][key] = own ? JSON.parse(JSON.stringify(S.state[key])) : null;
  update({ views });
  if (own) selectView(i);
  else {
    layoutViews();
    onSelect();
  }
  setStatus(own ? `view ${i + 1} has its own ${LINKS[key][1]}` : `view ${i + 1} follows the shared ${LINKS[key][1]} again`);
}

// View `i` selected: the probe, the fit and the editors are its.
export function selectView(i) {
  S.selectedView = i;
  panels.forEach((q, j) => q.el.classList.toggle('selected', j === i && panels.length > 1));
  layoutViews();
  onSelect();
}

function bindOrbit(p, i) {
  const ranges = () => S.choices.ranges.camera;
  let start = null;
  p.img.addEventListener('pointerdown', (e) => {
    if (!S.state) return;
    p.img.setPointerCapture(e.pointerId);
    start = { x: e.clientX, y: e.clientY, cam: { ...shown('camera', i) }, moved: false, box: e.shiftKey };
    if (S.state.clip && $('clip-drag').checked && !e.shiftKey) start.clip = { ...S.state.clip };
  });
  p.img.addEventListener('pointermove', (e) => {
    if (!start) return;
    const dx = e.clientX - start.x;
    const dy = e.clientY - start.y;
    if (!start.moved && Math.hypot(dx, dy) < 3) return;
    start.moved = true;
    if (start.box) {
      showBand(p, start, e);
      return;
    }
    if (start.clip) {
      const normal = turnedNormal(start.clip.normal, shown('camera', i), dx, dy);
      update({ clip: { normal, offset: start.clip.offset } }, 'preview');
      return;
    }
    // this panel's camera: its own where it has one, else the shared one (every linked view's)
    const cam = { ...shown('camera', i) };
    cam.azimuth = start.cam.azimuth - dx * 0.5;
    cam.elevation = clamp(start.cam.elevation + dy * 0.5, ranges().elevation);
    update({ camera: cam }, 'preview', false, i);
    drawTriads();
  });
  const end = (e) => {
    if (!start) return;
    const { moved, box } = start;
    const from = start;
    start = null;
    p.band.style.display = 'none';
    if (box && moved && e.type === 'pointerup') probeAt(p, i, e, from);
    else if (moved && from.clip) {
      $('clip-axis').value = 'custom';
      update({ clip: { ...S.state.clip } }, 'full');
    }
    else if (moved) update({ camera: { ...shown('camera', i) } }, 'full', false, i);
    else if (e.type === 'pointerup') probeAt(p, i, e);
  };
  p.img.addEventListener('pointerup', end);
  p.img.addEventListener('pointercancel', end);
  p.img.addEventListener(
    'wheel',
    (e) => {
      e.preventDefault();
      const cam = { ...shown('camera', i) };
      cam.zoom = clamp(cam.zoom * Math.exp(-e.deltaY * 0.0015), ranges().zoom);
      update({ camera: cam }, 'preview', false, i);
      settleLater();
    },
    { passive: false },
  );
}

// A click probes the voxel its ray meets; a shift-drag from `from` probes the box between the
// voxels the rays of its two corners meet.
function probeAt(p, i, e, from) {
  const r = p.img.getBoundingClientRect();
  const at = (cx, cy) => [
    clamp((cx - r.left) / r.width, [0, 1]),
    clamp((cy - r.top) / r.height, [0, 1]),
  ];
  const [x, y] = at(e.clientX, e.clientY);
  if (S.selectedView !== i) selectView(i);
  noteRange();
  if (from) {
    const [x2, y2] = at(from.x, from.y);
    showMark({ view: i, x: (x + x2) / 2, y: (y + y2) / 2 });
    send({ type: 'probe', view: i, x, y, x2, y2 });
    return;
  }
  showMark({ view: i, x, y });
  send({ type: 'probe', view: i, x, y });
}

// The rubber band of a shift-drag, from the drag's start to the pointer.
function showBand(p, from, e) {
  const r = p.pic.getBoundingClientRect();
  const b = p.band.style;
  b.display = 'block';
  b.left = `${Math.min(from.x, e.clientX) - r.left}px`;
  b.top = `${Math.min(from.y, e.clientY) - r.top}px`;
  b.width = `${Math.abs(e.clientX - from.x)}px`;
  b.height = `${Math.abs(e.clientY - from.y)}px`;
}

// A view's own window as the panel shows it ('t0:t1' or 't0:t1:stride'), '' when linked.
function windowText(w) {
  if (!w) return '';
  return `${w.t0}:${w.t1}${w.stride > 1 ? `:${w.stride}` : ''}`;
}

// 't0:t1[:stride]' as a window (end excluded), undefined when it is not one.
function parseWindow(text) {
  const m = /^(\d+):(\d+)(?::(\d+))?$/.exec(text);
  if (!m) return undefined;
  const [t0, t1, stride] = [Number(m[1]), Number(m[2]), Number(m[3] || 1)];
  const n = S.info ? S.info.shape.t : Infinity;
  return t1 > t0 && t1 <= n && stride >= 1 ? { t0, t1, stride } : undefined;
}

// The probe marker at {view, x, y} (fractions of the panel), or none.
export function showMark(at) {
  panels.forEach((q, j) => {
    const on = !!at && at.view === j;
    q.mark.style.display = on ? 'block' : 'none';
    if (on) {
      q.mark.style.left = `${at.x * 100}%`;
      q.mark.style.top = `${at.y * 100}%`;
    }
  });
}

// The slice panel's plane where it cuts the volume's box on view `view`'s panel (points:
// [x, y] fractions of the panel, slice.js), or on none.
export function showSliceOutline(view, points) {
  panels.forEach((q, j) => {
    const on = view === j && !!points;
    q.sliceCut.setAttribute('points', on ? points.map(([x, y]) => `${x},${y}`).join(' ') : '');
  });
}

// ------------------------------------------------------------------ frames
function fnv(bytes, h) {
  for (let k = 0; k < bytes.length; k++) {
    h ^= bytes[k];
    h = Math.imul(h, 16777619) >>> 0;
  }
  return h;
}

// A binary frame: header length (uint32, big-endian), JSON header, the panels' JPEGs.
export function onFrame(buf) {
  const n = new DataView(buf).getUint32(0);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  let at = 4 + n;
  let digest = 2166136261;
  header.views.forEach((v, i) => {
    const bytes = new Uint8Array(buf, at, v.bytes);
    at += v.bytes;
    digest = fnv(bytes, digest);
    const p = panels[i];
    if (!p) return;
    const url = URL.createObjectURL(new Blob([bytes], { type: 'image/jpeg' }));
    const old = p.img.dataset.url;
    p.img.src = url;
    p.img.dataset.url = url;
    if (old) URL.revokeObjectURL(old);
    showLabel(p, S.state.views[i], v.label);
    showNote(p, v.note);
  });
  // Where the probed voxel is in this frame (it moves with the camera; none before a probe).
  if (viewer.probe && viewer.probe.values) showMark(header.probe || null);
  // The clip plane's cut through the box on each panel, under its camera.
  const cut = (c) => (c || []).map(([x, y]) => `${x},${y}`).join(' ');
  panels.forEach((p, i) => {
    p.outline.setAttribute('points', cut(header.clip_outlines[i]));
    // With the box on, its labelled edges under the view's camera (box_axes.js).
    showAxes(p.axes, header.axes ? header.axes[i] : null);
  });
  S.legends = header.legends; // each view's: a view with its own window has its own
  S.legend = S.legends[0]; // the first view's, the timeline's
  S.colorbars = header.colorbars || null; // each view's data colour bar, null where TF is white
  S.countbars = header.countbars || null; // a count view's bar, in place of its time legend
  S.focus = header.focus || null;
  drawLegends();
  const now = performance.now();
  const t0 = sentAt.get(header.id);
  viewer.frames += 1;
  if (header.quality === 'full') viewer.full += 1;
  viewer.last = {
    id: header.id, seq: header.seq, quality: header.quality, digest, views: header.views.length,
    timings: header.timings, roundTripMs: t0 === undefined ? null : now - t0,
    level: header.level || 0, refining: !!header.refining,
  };
  shell.dataset.frames = viewer.frames;
  viewer.levels.push(header.level || 0);
  if (viewer.levels.length > 50) viewer.levels.shift();
  shell.dataset.level = header.level || 0;
  shell.dataset.refining = header.refining ? 'yes' : 'no';
  if (header.id === null || header.id >= viewer.sent) frameArrived();
  showTimings(header);
  drawTriads();
  drawTimeline();
  drawProbe();
  noteRange(); // the window or a mode may have changed since the curve was fitted
}

// A (nearly) empty view's note, or none: a strip at the picture's foot (style.css) of as many
// lines as about a fifth of the picture holds (two at least), the whole text in its tooltip.
function showNote(p, note) {
  p.note.textContent = note || '';
  p.note.title = note || '';
  p.note.hidden = !note;
  if (!note) return;
  const lines = Math.max(2, Math.floor((0.22 * p.pic.clientHeight - 8) / 15));
  p.note.style.setProperty('--note-lines', String(lines));
}

// A panel's caption in its head band, beside the mode and order menus that say its first part:
// that part ('alpha, forward, ') is the one cut short where the band is narrow, so the steps
// (or times) after it always show. The whole caption is the label's text and its tooltip.
function showLabel(p, view, label) {
  const what = view ? `${view.mode}, ${view.order || S.choices.orders[0]}, ` : '';
  const cut = what && label.startsWith(what) ? what.length : 0;
  const head = document.createElement('span');
  head.className = 'what';
  head.textContent = label.slice(0, cut);
  const tail = document.createElement('span');
  tail.className = 'when';
  tail.textContent = label.slice(cut);
  p.label.replaceChildren(head, tail);
  p.label.title = label;
}

// How far the refine of the frame shown got (a `progress` message of what 'refine'): the
// status line says it and that Esc cancels it; a frame's timings replace it.
export function showRefineProgress(msg) {
  viewer.refineProgress = msg;
  // The answer to `cancel`, or a note that left before it: cancelRefine said so already.
  if (msg.stage === 'cancelled' || shell.dataset.refining !== 'yes') return;
  const what = { integrating: 'slabs', sliding: 'parts' }[msg.stage] || 'steps';
  const of = msg.views > 1 ? ` (view ${msg.view + 1} of ${msg.views})` : '';
  setStatus(`refining to full resolution: ${msg.stage} ${msg.done}/${msg.total} ${what}${of} · Esc cancels`);
}

// Stop refining the frame shown (Esc): the server keeps the coarse frame until the next input.
export function cancelRefine() {
  if (shell.dataset.refining !== 'yes') return;
  send({ type: 'cancel' });
  shell.dataset.refining = 'cancelled';
  setStatus('refine cancelled: the coarse frame stays until the next change');
}

// The status line: what the frame shows and what it took (recoloured or integrated, and why
// not recoloured, streamed or off the GPU where so), and the round trip; the stages' times and
// the frame's sizes are in its tooltip (the whole line was a wall of milliseconds).
function showTimings(h) {
  const t = h.timings;
  const v = h.views[0];
  const kb = h.views.reduce((s, x) => s + x.bytes, 0) / 1024;
  const rt = viewer.last.roundTripMs;
  const shape = (h.level_shape || []).slice().reverse().join('×');
  const level = h.level ? `level ${h.level} (${shape}) · refining…` : `full resolution (${shape})`;
  const parts = [
    level,
    // a TF edit that only recoloured (max, min, first_hit, change) integrated nothing; a
    // camera move or a refine's last frame neither: only drawn again
    ...(t.recolour_ms > 0 ? [`recoloured in ${t.recolour_ms.toFixed(0)} ms`] : []),
    ...(t.integrate_ms > 0
      ? [`integrated in ${t.integrate_ms.toFixed(0)} ms${t.incremental ? ' (incremental)' : ''}`]
      : []),
    ...(t.integrate_ms > 0 || t.recolour_ms > 0 ? [] : [`drawn in ${t.render_ms.toFixed(0)} ms`]),
    // an edit of a mode that recolours integrated instead: why
    ...h.views.filter((x) => x.why_integrated).slice(0, 1).map((x) => `not recoloured: ${x.why_integrated}`),
    // a GPU whose memory cannot hold the window: its steps travel for every integration
    ...(t.steps_on_host ? [`steps not on the GPU: ${t.steps_on_host}`] : []),
    // the memory limit leaves the window's steps too little room: read from the store each time
    ...(t.streamed ? [`${t.streamed} (a larger --memory keeps the window in memory)`] : []),
    ...(h.reduced ? ['reduced for speed, sharpening…'] : []),
  ];
  if (rt !== null) parts.push(`round trip ${rt.toFixed(0)} ms`);
  setStatus(parts.join(' · '));
  $('status').title = [
    `integrate ${t.integrate_ms.toFixed(1)} ms (reading steps ${t.read_ms.toFixed(1)} ms of it)`,
    `recolour ${t.recolour_ms.toFixed(1)} ms`,
    `upload ${t.upload_ms.toFixed(1)} ms`,
    `render ${t.render_ms.toFixed(1)} ms`,
    `encode ${t.encode_ms.toFixed(1)} ms`,
    `server ${t.server_ms.toFixed(1)} ms`,
    `${h.views.length}× ${v.width}×${v.height} ${h.format} ${kb.toFixed(0)} KB (${h.quality})`,
  ].join(' · ');
}
