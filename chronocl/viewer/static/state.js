// What the page shows (made by pageState) and the small helpers every part of it uses.
// `viewer` (window.viewer on the page) is also read by the tests and the benchmarks.
//
// The viewer's elements are looked up (`$`) in its root: the document for the page, a shadow
// root for each notebook widget (chronocl/notebook: every widget loads its own instance of
// these modules, so each has its own root and state).

let root = document;
export const $ = (id) => root.getElementById(id);

// The page's state (S) and viewer, made once by app.js and given to each module's bind
// function (no module imports them). `host` says where the viewer lives: `root` (whose
// getElementById finds its elements), `shell` (the element holding the whole viewer, whose
// classes and data attributes the style sheet reads), `keys` (where its shortcuts listen),
// `fragment` (whether the address's #state= carries the state) and `global` (whether the
// viewer is also window.viewer). The page's defaults are the document's.
export function pageState(host = {}) {
  root = host.root || document;
  const S = {
    choices: null, // the server's `info` message: modes, orders, presets, defaults, bounds
    info: null, // the data set: shape, stats
    state: null, // protocol state (camera, views, window, data_tf, time_tf, ...)
    histogram: null,
    fits: [], // the fits made on this data set, {range, window, mode}, newest last (fit.js)
    zoom: [0, 1], // data TF editor's visible range of u
    selectedPoint: 1,
    selectedView: 0,
    legend: [],
    focus: null, // the world box the last frame framed (history.js keeps it with the state)
    playing: false,
    initialCamera: null, // the data set's opening camera (camera reset returns to it)
    columns: 1, // panels per row on screen (layoutViews); saved images and movies use it too
  };
  const viewer = {
    frames: 0, full: 0, sent: 0, last: null, errors: [], probe: null, downloads: [], S,
    levels: [],  // the level of each frame received, latest last (at most 50)
    playLog: [],  // {at, t0} for each slide play made, latest last (at most 200)
    connects: 0,  // sockets opened (1 + reconnects)
  };
  if (host.global !== false) window.viewer = viewer;
  const shell = host.shell || document.body;
  return { S, viewer, shell, keys: host.keys || document, fragment: host.fragment !== false };
}

// A canvas sized to its box in device pixels; returns its context (in CSS pixels) and size.
export function canvasSize(c) {
  const r = c.getBoundingClientRect();
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(r.width * dpr));
  const h = Math.max(1, Math.round(r.height * dpr));
  if (c.width !== w || c.height !== h) {
    c.width = w;
    c.height = h;
  }
  const ctx = c.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  return [ctx, r.width, r.height];
}

export const fmt = (v) =>
  Math.abs(v) >= 1e4 || (Math.abs(v) < 1e-3 && v !== 0) ? v.toExponential(2) : +v.toPrecision(4);

export const clamp = (v, [lo, hi]) => Math.max(lo, Math.min(hi, v));

let statusTimer = 0;
export function setStatus(text, bad = false) {
  const el = $('status');
  if (!bad && el.classList.contains('error') && Date.now() < statusTimer) return;
  el.textContent = text;
  el.classList.toggle('error', bad);
  if (bad) statusTimer = Date.now() + 4000;
}
