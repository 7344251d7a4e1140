// The slice panel: one plane (x, y or z at an index) of the selected view's chronovolume, as
// `chronocl render --slice` draws it (the server's `slice` reply: chronocl/viewer/slicing.py),
// scaled to the panel's width; and the read-out under the pointer over its voxel grid (the
// reply's `box`, in each of its pictures: the colours and the step map): the voxel, its
// position in data units, the step that won it, its time and the series' value there. The
// picture is asked for while the panel is open: when the axis or index changes (debounced)
// and after a full frame of a changed view (its window, mode, TFs, camera, the view
// selected), so it follows what the view shows.
// The picture can also be shown larger over the views (#slice-big), read out the same way.
// The plane's outline is drawn on the view's panel (the reply's `outline`, under the camera
// the view had when it was asked for; hidden while the camera moves, asked again after).
// A click does not pin a probe: the probe takes a ray through a view's panel, not a voxel.

import { flushUpdates, send, shown } from './connection.js';
import { $ } from './state.js';
import { showSliceOutline } from './views.js';

// The page's state (state.js: pageState), made by app.js and given to bindSlice.
let S;
let viewer;

const ASK_MS = 120; // the picture asked this long after the last axis or index change
const HOVER_MS = 80; // at most one read-out asked in this time
let askTimer = 0;
let hoverTimer = 0;
let hoverAt = 0;
let hoverNext = null;
let hoverLast = null; // where the pointer rests on the grid: read out again for a new picture
let asked = null; // what the last picture was asked for (sliceKey)
let pictureId = 0; // the id of the newest picture asked for
let hoverId = 0; // the id of the newest read-out asked for
// One picture and one read-out in flight at a time (the render thread answers them between
// frames, and holds at most 8 requests): the next is asked when the last one's answer comes.
// (an answer lost with its socket frees them after BUSY_MS)
const BUSY_MS = 10_000;
const SIDE_INSET = 40; // the side panel's padding (20), border (1), picture border (2), scrollbar
let pictureBusy = 0; // when the picture in flight was asked for (0: none)
let hoverBusy = 0;
const busy = (since) => since > 0 && performance.now() - since < BUSY_MS;
let shownKey = null; // what the picture shown was asked for

const HINT = 'move the pointer over the slice: the voxel, its step, time and value; click: probe v(t) there';

// Pictures are asked for while the panel is open or the slice is shown over the views.
const open = () => ($('slice-panel').open && $('side').offsetWidth > 0) || !$('slice-big').hidden;

// The volume's voxels along `axis`, from the data set's shape {t, z, y, x}.
const extent = (axis) => (S.info ? S.info.shape[axis] : 1);

// The slice chosen, as the protocol names it ("z=16").
const spec = () => `${$('slice-axis').value}=${$('slice-index').value}`;

// The slider over the chosen axis's voxels (its index kept where it still fits).
function syncSlider(middle = false) {
  const n = extent($('slice-axis').value);
  const el = $('slice-index');
  el.max = String(n - 1);
  if (middle || +el.value > n - 1) el.value = String(Math.floor((n - 1) / 2));
  $('slice-at').textContent = `${el.value} / ${n - 1}`;
}

// The room for the picture in device pixels (the server shares its width among the pictures,
// slicing.panel_size): the side panel's width, or, shown over the views, the room there.
function pictureSize() {
  const dpr = window.devicePixelRatio || 1;
  const fit = (v) => Math.max(64, Math.min(1024, Math.round(v * dpr)));
  const big = $('slice-big');
  if (!big.hidden && big.clientWidth > 0) {
    // less the title, margins and two lines of read-out; in 16-pixel steps, as the panel's
    const [w, h] = [fit(big.clientWidth - 20), fit(Math.max(64, big.clientHeight - 80))];
    return [Math.max(64, w - (w % 16)), Math.max(64, h - (h % 16))];
  }
  // The side panel's width less its padding, border and a scrollbar's room, whether one shows
  // or not (the picture's own height makes one come and go: it asked again, at another width);
  // in whole 16-pixel steps, so a few pixels' change asks for no new picture.
  const width = fit($('side').offsetWidth - SIDE_INSET);
  return [Math.max(64, width - (width % 16)), 1024];
}

// What the picture shows: the slice, and what the selected view is drawn from and with.
function sliceKey() {
  if (!S.info || !S.state) return null;
  const i = S.selectedView;
  return JSON.stringify([
    S.info.index, spec(), i, S.state.views[i], S.state.window, shown('data_tf'), shown('time_tf'),
    S.state.enhance, S.state.threshold, S.state.background, S.state.size, shown('camera'),
    pictureSize(),
  ]);
}

function ask(delay = ASK_MS) {
  clearTimeout(askTimer);
  askTimer = setTimeout(() => {
    const key = sliceKey();
    if (!open() || key === null) return;
    if (busy(pictureBusy)) {
      // asked again when it answers; one that never comes, once it is stale
      askTimer = setTimeout(() => ask(0), BUSY_MS - (performance.now() - pictureBusy) + 1);
      return;
    }
    asked = key;
    flushUpdates(); // the server draws it first, then answers from what it drew
    const id = send({ type: 'slice', view: S.selectedView, slice: spec(), size: pictureSize() });
    pictureBusy = id ? performance.now() : 0;
    pictureId = id || pictureId;
  }, delay);
}

// After each frame (app.js): a full, settled frame of a view changed since the picture was
// asked for asks again; the slider follows the data set's shape.
export function sliceFrame() {
  if (!open() || !S.info) return;
  syncSlider();
  const key = sliceKey();
  if (!viewer.slice || key !== asked) showSliceOutline(null); // stale: the camera or view moved
  const last = viewer.last;
  if (last && (last.quality !== 'full' || last.refining)) return;
  if (key !== asked) ask(0);
}

// The read-out at (u, v) of the grid: asked at most every HOVER_MS, the last point kept.
function askReadout(u, v) {
  hoverNext = { u, v };
  hoverLast = hoverNext;
  const wait = hoverAt + HOVER_MS - performance.now();
  clearTimeout(hoverTimer);
  const go = () => {
    if (!hoverNext || !S.state) return;
    if (busy(hoverBusy)) {
      // the answer sends the point kept; one that never comes, once it is stale
      hoverTimer = setTimeout(go, BUSY_MS - (performance.now() - hoverBusy) + 1);
      return;
    }
    hoverAt = performance.now();
    const msg = { type: 'slice', view: S.selectedView, slice: spec(), picture: false, ...hoverNext };
    hoverNext = null;
    const id = send(msg);
    hoverBusy = id ? performance.now() : 0;
    hoverId = id || hoverId;
  };
  if (wait <= 0) go();
  else hoverTimer = setTimeout(go, wait);
}

// The pointer's (u, v) in [0, 1] of the voxel grid (across from the left, down from the top),
// or null off it. The reply's `box` is where the grid lies in each of its pictures (the
// colours, and the step map where the mode keeps one: `layout.pictures`, in the picture's
// pixels), so either one reads out.
function gridPoint(e, img) {
  const msg = viewer.slice;
  if (!msg || !img.naturalWidth) return null;
  const r = img.getBoundingClientRect();
  const px = ((e.clientX - r.left) * img.naturalWidth) / r.width;
  const py = ((e.clientY - r.top) * img.naturalHeight) / r.height;
  const [bx, by, bw, bh] = msg.box;
  for (const [x0, y0] of msg.layout.pictures) {
    const u = (px - x0 - bx) / bw;
    const v = (py - y0 - by) / bh;
    if (u >= 0 && u <= 1 && v >= 0 && v <= 1) return { u, v };
  }
  return null;
}

function readoutText(msg) {
  const r = msg.readout;
  const p = r.position;
  const where = `x=${r.voxel.x} y=${r.voxel.y} z=${r.voxel.z} (${[p.x, p.y, p.z].map((q) => +q.toPrecision(6)).join(', ')})`;
  if (msg.t_index === false) return `${where}: this view's mode keeps no winning step (no t_index)`;
  return r.text;
}

// The picture or read-out in flight answered: the next one asked for goes now (a picture where
// the view changed meanwhile, the read-out at the last point the pointer reached).
function answered(picture) {
  if (picture) {
    pictureBusy = 0;
    if (open() && sliceKey() !== asked) ask(0);
  } else {
    hoverBusy = 0;
    if (hoverNext) askReadout(hoverNext.u, hoverNext.v);
  }
}

// The read-out of `msg` (a reply to the pointer's point) under both pictures, or the hint.
function showReadout(msg) {
  viewer.sliceReadout = msg.readout;
  viewer.sliceReadoutId = msg.id;
  for (const id of ['slice-readout', 'slice-big-readout']) $(id).textContent = readoutText(msg);
}

function clearReadout() {
  viewer.sliceReadout = null;
  for (const id of ['slice-readout', 'slice-big-readout']) $(id).textContent = HINT;
}

// A `slice` reply: the picture (an older one than the newest asked for is dropped) and, with
// a point, its read-out.
export function onSlice(msg) {
  if (msg.id === hoverId) answered(false);
  if (msg.id === pictureId) answered(true);
  if (!msg.png) {
    // a read-out alone (the pointer over the picture shown): the picture stays
    if (msg.readout && msg.id >= hoverId && viewer.slice && msg.slice === viewer.slice.slice) {
      showReadout(msg);
    }
    return;
  }
  if (msg.id !== null && msg.id < pictureId) return; // a newer picture was asked for
  viewer.slice = msg;
  if (asked !== shownKey) {
    // another picture (the view or the slice changed): the read-out of the last one goes
    shownKey = asked;
    if (!msg.readout) {
      clearReadout();
      if (hoverLast) askReadout(hoverLast.u, hoverLast.v); // the pointer still rests there
    }
  }
  for (const id of ['slice-pic', 'slice-big-pic']) {
    const img = $(id);
    if (img.getAttribute('src') !== msg.png) img.src = msg.png;
    img.dataset.id = msg.id;
  }
  $('slice-pic').hidden = false;
  showSliceOutline(sliceKey() === asked ? msg.view : null, msg.outline);
  const g = msg.grid;
  const what = `${msg.slice} of view ${msg.view + 1}: ${g.across} across, ${g.up} up (${g.cols}×${g.rows} voxels)`;
  $('slice-note').textContent = what;
  $('slice-note').classList.remove('error');
  $('slice-big-title').textContent = `Slice ${what}`;
  if (msg.readout && msg.id >= hoverId) {
    showReadout(msg);
  }
}

// An error answering a slice request: said under the picture.
export function sliceFailed(msg) {
  if (msg.id === null || (msg.id !== pictureId && msg.id !== hoverId)) return;
  answered(msg.id === pictureId);
  $('slice-note').textContent = msg.message;
  $('slice-note').classList.add('error');
}

export function bindSlice(page) {
  ({ S, viewer } = page);
  viewer.slice = null;
  viewer.sliceReadout = null;
  viewer.sliceReadoutId = -1; // the request its read-out answers
  const moved = () => {
    clearReadout();
    ask();
  };
  $('slice-axis').addEventListener('change', () => {
    syncSlider(true);
    moved();
  });
  $('slice-index').addEventListener('input', () => {
    syncSlider();
    moved();
  });
  $('slice-panel').addEventListener('toggle', () => {
    if (!open()) showSliceOutline(null);
    if (!open() || !S.info) return;
    syncSlider();
    asked = null;
    ask(0);
  });
  for (const id of ['slice-pic', 'slice-big-pic']) {
    const img = $(id);
    img.addEventListener('pointermove', (e) => {
      const at = gridPoint(e, img);
      img.classList.toggle('on-grid', !!at);
      if (at) askReadout(at.u, at.v);
    });
    // A click pins the probe there: v(t) at that voxel in the probe panel, marked on the view.
    img.addEventListener('click', (e) => {
      const at = gridPoint(e, img);
      if (at && viewer.slice) {
        send({ type: 'probe', view: viewer.slice.view, slice: viewer.slice.slice, ...at });
      }
    });
    img.addEventListener('pointerleave', () => {
      hoverNext = hoverLast = null;
      clearTimeout(hoverTimer);
    });
  }
  const large = (show) => {
    $('slice-big').hidden = !show;
    $('slice-large').setAttribute('aria-expanded', String(show));
    if (open()) ask(0); // drawn again at the size it is shown at
  };
  $('slice-large').addEventListener('click', () => large($('slice-big').hidden));
  $('slice-big-close').addEventListener('click', () => {
    large(false);
    if (!open()) showSliceOutline(null);
  });
}
