// The events panel: Find events labels the selected view's window in the server (beside the
// frames: chronocl/viewer/events_panel.py), a step showing where the data TF's opacity exceeds
// a value or where the values reach one; the panel lists the window's events (kind, step,
// size, centroid) and tracks. A click on an event moves the window to hold its step and frames
// it (the update's `focus`: the camera turns about the event's centroid); a click on a track,
// or on an event, plots that track's size and mean value over the series (plot.js, as the
// probe's curve is drawn) and highlights it in the views: a line through its centroids; so does
// a click on a feature in a view (the probe's answer names the feature's track).
// `markers` draws the events found (and the track highlighted) in the views and saved PNGs.
// A find is given up by the server when the window changes before it ends; without the
// `events` extra the panel says how to install it and the rest of the viewer works as before.

import { send, update } from './connection.js';
import { drawTimePlot } from './plot.js';
import { $, fmt, setStatus } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindEvents.
let S;
let viewer;

const KINDS = { birth: '✚', death: '✖', merge: '⤙', split: '⤚', 'merge-split': '⤧', entry: '⇥', exit: '⇤' };
let lastBy = { opacity: null, value: null }; // the threshold typed for each kind of mask

function text(t, bad = false) {
  const el = $('events-text');
  el.textContent = t;
  el.classList.toggle('error', bad);
}

// The server's `info`: whether feature tracking is installed, the choices and the default.
export function fillEvents(choices) {
  const ev = choices.events;
  const conn = $('events-conn');
  conn.replaceChildren(
    ...ev.connectivity.map((n) => {
      const o = document.createElement('option');
      o.value = n;
      o.textContent = String(n);
      return o;
    }),
  );
  conn.value = String(ev.connectivity[ev.connectivity.length - 1]);
  lastBy.opacity = ev.opacity;
  if ($('events-by').value === 'opacity') $('events-threshold').value = ev.opacity;
  $('events-find').disabled = !ev.available;
  if (!ev.available) text(`feature tracking is not installed: ${ev.install}`, true);
}

function syncBy() {
  const by = $('events-by').value;
  const input = $('events-threshold');
  if (by === 'value' && lastBy.value === null && S.info) {
    lastBy.value = +fmt(S.info.vmin + 0.5 * (S.info.vmax - S.info.vmin));
  }
  input.value = lastBy[by];
  input.step = by === 'opacity' ? '0.01' : 'any';
  for (const [k, v] of [['min', 0], ['max', 0.99]]) {
    if (by === 'opacity') input.setAttribute(k, v);
    else input.removeAttribute(k); // a value may be anything the data holds
  }
  input.title = by === 'opacity'
    ? "a voxel is a feature's where the data TF's opacity exceeds this (0 to 0.99)"
    : "a voxel is a feature's where its value is at least this (data units)";
}

function findEvents() {
  if (!S.state) return;
  const by = $('events-by').value;
  const v = Number($('events-threshold').value);
  const bound = S.choices.events.opacity_range;
  if (!Number.isFinite(v) || (by === 'opacity' && (v < bound[0] || v > bound[1]))) {
    text(by === 'opacity' ? `give an opacity from ${bound[0]} to ${bound[1]}` : 'give a value', true);
    return;
  }
  lastBy[by] = v;
  const msg = { type: 'events', action: 'find', view: S.selectedView, by, [by]: v,
    connectivity: Number($('events-conn').value), show: $('events-markers').checked };
  viewer.events = { finding: send(msg) };
  text('finding events…');
}

// The server's answer to a find (or to a clear, or a find without the extra).
export function onEvents(msg) {
  if (msg.cleared) return;
  if (msg.missing) {
    viewer.events = { missing: msg.missing };
    text(`feature tracking is not installed: ${msg.missing}`, true);
    return;
  }
  if (!viewer.events || viewer.events.finding !== msg.id) return; // a find replaced since
  if (msg.cancelled) {
    viewer.events = { cancelled: msg.cancelled };
    text(`find given up: ${msg.cancelled}`, true);
    return;
  }
  viewer.events = { found: msg, track: null };
  const w = msg.window;
  const more = msg.events_total > msg.events.length ? ` (the first ${msg.events.length} listed)` : '';
  text(`window ${w[0]}:${w[1]}${w[2] > 1 ? ':' + w[2] : ''}, ${msg.mask}: ${msg.describe}${more}`);
  listEvents(msg);
  listTracks(msg);
  if (msg.tracks.length) selectTrack(msg.tracks[0].id);
  else drawTrack();
}

// A probe's answer: a click on a feature of the events found plots and highlights its track.
export function eventsProbed(msg) {
  if (!msg.track || !viewer.events || !viewer.events.found) return;
  if (msg.track.find !== undefined && msg.track.find !== viewer.events.found.id) return; // another find's
  selectTrack(msg.track.track, true);
  const t = $('events-track-text');
  t.textContent = `picked in the view (step ${msg.track.step}): ${t.textContent}`;
}

// An error answering the find waiting (a threshold the data TF cannot meet, a failed read).
export function eventsFailed(id) {
  if (!viewer || !viewer.events || viewer.events.finding !== id || id === null) return;
  viewer.events = { failed: id };
  text('find failed: see the status line', true);
}

// How far a find got (sent after its first second).
export function eventsProgress(msg) {
  if (!viewer.events || viewer.events.finding !== msg.id) return;
  text(`finding events: ${msg.stage} ${msg.done + 1}/${msg.total}…`);
}

// A new data set: the events found belong to the old one. `tell`: the server forgets them too;
// false on a (re)connect, whose new socket's worker has none (nor the find running on the old).
export function clearEvents(tell = true) {
  if (!viewer) return;
  if (tell && viewer.events && viewer.events.found) send({ type: 'events', action: 'clear' }); // (no markers)
  viewer.events = null;
  $('events-list').replaceChildren();
  $('events-tracks').replaceChildren();
  drawTrack();
  if (S.choices && S.choices.events.available) text('find the features of the selected view\'s window and what happens to them');
}

const xyz = (c) => `(${c.map((v) => Math.round(v * 10) / 10).join(', ')})`; // voxels, to a tenth

function listEvents(msg) {
  const rows = msg.events.map((e, i) => {
    const li = document.createElement('li');
    li.dataset.index = i;
    li.dataset.kind = e.kind;
    li.tabIndex = 0;
    li.title = `${e.kind} between steps ${e.step} and ${e.next_step}${e.at_boundary ? ', at the boundary' : ''}: click to move the window there and frame it`;
    li.innerHTML = '<span class="ev-kind"></span><span class="ev-step"></span><span class="ev-size"></span><span class="ev-at"></span>';
    li.children[0].textContent = `${KINDS[e.kind] || '•'} ${e.kind}`;
    li.children[1].textContent = `${e.step}→${e.next_step}`;
    li.children[2].textContent = String(e.size);
    li.children[3].textContent = xyz(e.centroid);
    return li;
  });
  if (!rows.length) {
    const li = document.createElement('li');
    li.className = 'none';
    li.textContent = 'no events in this window: every feature continues';
    rows.push(li);
  } else {
    const head = document.createElement('li');
    head.className = 'head';
    head.innerHTML = '<span class="ev-kind">event</span><span class="ev-step">steps</span><span class="ev-size">voxels</span><span class="ev-at">centroid x, y, z</span>';
    rows.unshift(head);
  }
  $('events-list').replaceChildren(...rows);
}

function listTracks(msg) {
  const rows = msg.tracks.map((t) => {
    const li = document.createElement('li');
    li.dataset.track = t.id;
    li.tabIndex = 0;
    const sizes = `${t.size[0]}→${t.size[t.size.length - 1]} vox`;
    li.textContent = `track ${t.id}: steps ${t.start}–${t.end} (${t.length}), ${sizes}`;
    li.title = 'click to plot its size and mean value over time and draw its path in the views';
    return li;
  });
  $('events-tracks').replaceChildren(...rows);
}

// `id` plotted; `highlight`: drawn in the views too (a line through its centroids).
function selectTrack(id, highlight = false) {
  if (!viewer.events || !viewer.events.found) return;
  viewer.events.track = id;
  if (highlight) {
    viewer.events.highlighted = id;
    send({ type: 'events', action: 'track', track: id, find: viewer.events.found.id });
  }
  for (const li of $('events-tracks').children) li.classList.toggle('selected', Number(li.dataset.track) === id);
  drawTrack();
}

// The selected track's size and mean value at each of its steps, over the whole series.
export function drawTrack() {
  const found = viewer && viewer.events && viewer.events.found;
  const t = found && found.tracks.find((k) => k.id === viewer.events.track);
  const sizeCanvas = $('events-size');
  const valueCanvas = $('events-value');
  sizeCanvas.hidden = valueCanvas.hidden = !t || !S.info; // (shown before drawn: sized then)
  if (!t || !S.info) {
    drawTimePlot(sizeCanvas, {});
    drawTimePlot(valueCanvas, {});
    $('events-track-text').textContent = found ? 'click a track (or an event) to plot it' : '';
    return;
  }
  const T = S.info.shape.t;
  const size = new Array(T).fill(null);
  const value = new Array(T).fill(null);
  t.steps.forEach((s, k) => {
    size[s] = t.size[k];
    value[s] = t.value[k];
  });
  const common = { T, steps: t.steps, labels: S.info.time_labels };
  drawTimePlot(sizeCanvas, { ...common, lo: 0, hi: Math.max(...t.size), values: size, title: `track ${t.id}: size (voxels)` });
  drawTimePlot(valueCanvas, { ...common, lo: S.info.vmin, hi: S.info.vmax, values: value, colour: '#8fd694', title: 'mean value' });
  const last = t.centroid[t.centroid.length - 1];
  $('events-track-text').textContent = `track ${t.id}: steps ${t.start}–${t.end}, centroid ${xyz(t.centroid[0])} → ${xyz(last)}`;
}

// The window (the view's own, where it has one) moved to hold the event's steps, keeping its
// width and stride, and the camera framing the event (its `focus` box, about its centroid).
function goTo(i) {
  const found = viewer.events && viewer.events.found;
  if (!found || !S.info) return;
  const e = found.events[i];
  const T = S.info.shape.t;
  const view = Math.min(found.view, S.state.views.length - 1);
  const own = S.state.views[view].window;
  const w = own || S.state.window;
  const width = w.t1 - w.t0;
  let { t0, t1 } = w;
  if (!(e.step >= t0 && e.next_step < t1)) {
    t0 = Math.max(0, Math.min(T - width, Math.round((e.step + e.next_step + 1 - width) / 2)));
    t1 = t0 + width;
  }
  const win = { t0, t1, stride: w.stride };
  const fields = own
    ? { views: S.state.views.map((v, k) => (k === view ? { ...v, window: win } : v)) }
    : { window: win };
  update({ ...fields, focus: e.focus }, 'full');
  delete S.state.focus; // a request, not part of the page's state
  for (const li of $('events-list').children) li.classList.toggle('selected', Number(li.dataset.index) === i);
  viewer.events.event = i;
  if (e.tracks.length) selectTrack(e.tracks[0], true);
  setStatus(`${e.kind} between steps ${e.step} and ${e.next_step}: window ${t0}:${t1}`);
}

function onListKey(e, act) {
  if (e.key !== 'Enter' && e.key !== ' ') return;
  e.preventDefault();
  e.stopPropagation(); // the row's key, not the page's (Space there is not play / pause)
  act(e);
}

export function bindEvents(page) {
  ({ S, viewer } = page);
  viewer.events = null;
  $('events-find').addEventListener('click', findEvents);
  $('events-by').addEventListener('change', syncBy);
  $('events-markers').addEventListener('change', () => {
    send({ type: 'events', action: 'markers', show: $('events-markers').checked });
  });
  const eventAt = (e) => {
    const li = e.target.closest('li[data-index]');
    if (li) goTo(Number(li.dataset.index));
  };
  const trackAt = (e) => {
    const li = e.target.closest('li[data-track]');
    if (li) selectTrack(Number(li.dataset.track), true);
  };
  $('events-list').addEventListener('click', eventAt);
  $('events-list').addEventListener('keydown', (e) => onListKey(e, eventAt));
  $('events-tracks').addEventListener('click', trackAt);
  $('events-tracks').addEventListener('keydown', (e) => onListKey(e, trackAt));
}
