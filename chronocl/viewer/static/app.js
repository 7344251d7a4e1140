// chronocl viewer page: sends state changes to the server, shows the frames it renders. Plain
// ES modules, no build step, no dependencies. This module routes the server's text messages
// and wires the parts together (`start`: main.js starts the page on its WebSocket, a notebook
// widget starts it in its cell output on its comm, chronocl/notebook/widget.js):
//   state.js       what the page shows (S, window.viewer: made here, given to each bind) and helpers
//   connection.js  the transport (WebSocket or widget comm): send, coalesced updates
//   views.js       the view panels, orbit/zoom/probe input, incoming frames
//   timeline.js    the window brush, play (speed, loop/bounce)
//   orientation.js the axes triads, camera reset, standard views
//   keys.js        the keyboard shortcuts (one table) and the `?` list
//   tf_editor.js   the data transfer function editor
//   fit.js         Fit to window: the data TF's range fitted as the command line fits it
//   probe.js       the v(t) plot of a probed voxel
//   plot.js        the small plot over the series' steps (the probe's, the events panel's)
//   slice.js       the slice panel: a plane of the selected view, the read-out under the pointer
//   events.js      the events panel: Find events, the events and tracks, markers
//   legend.js      the time legend and the data colour bar drawn in each view
//   time_follow.js time colours that follow a colour-map preset (lightness under its hue)
//   history.js     the undo history: undo / redo of every edit
//   snapshot.js    the saved state (a snapshot): the URL fragment (#state=), Save / Load session
//   controls.js    the other controls, filled from the server's choices
//   shading.js     the lighting toggle and strengths

import { connect, disconnect, frameArrived, send, showFrameProgress, shown, update } from './connection.js';
import { bindControls, fillControls, movieProgress, syncControls } from './controls.js';
import {
  bindEvents, clearEvents, drawTrack, eventsFailed, eventsProbed, eventsProgress, fillEvents, onEvents,
} from './events.js';
import { bindFit, fitFailed, forgetFits, onFit, refitMode } from './fit.js';
import { bindHistory, noteFocus, resetHistory } from './history.js';
import { bindKeys, unbindKeys } from './keys.js';
import { bindLegend, drawLegends } from './legend.js';
import { bindOrientation, drawTriads } from './orientation.js';
import { bindProbe, clearProbe, drawProbe, onProbe } from './probe.js';
import { bindShading, syncShading } from './shading.js';
import { bindSlice, onSlice, sliceFailed, sliceFrame } from './slice.js';
import { bindSnapshot, fragmentSnapshot, loadSnapshot } from './snapshot.js';
import { $, pageState, setStatus } from './state.js';
import { bindTF, drawTF, fillColormaps, noteHistogram, tookHistogram } from './tf_editor.js';
import { bindTimeFollow } from './time_follow.js';
import { bindTimeline, drawTimeline, onSteps } from './timeline.js';
import { bindViews, fillSelect, layoutViews, onFrame, showMark, showRefineProgress } from './views.js';

// The page's state, given to every module that reads or changes it (made by `start`).
let page;
let S;
let viewer;

// After a reconnect: the state the page had, sent back once the data set is open again.
let restore = null;
// The id of the load of the snapshot the URL carried (#state=), until the server answers it.
let urlLoad = null;

// The first message on every socket: the data sets, and the modes, menus, defaults and bounds
// to offer. On a socket opened again (the server restarted) the page reopens its data set.
function onInfo(msg) {
  S.choices = msg;
  fillColormaps();
  fillControls(msg);
  clearEvents(false); // a new socket's worker has no events found, nor a find running
  fillEvents(msg);
  fillSelect(
    $('dataset'),
    // shape is the array's (T, Z, Y, X); the label reads x×y×z like --dims and info (n³ for a
    // cube), so name and shape fit the menu; the whole of both are its tooltip (datasetTitle).
    msg.datasets.map((d) => ({
      name: d.index,
      label: `${d.name} (${dims(d.shape, true)}, ${d.shape[0]} steps)`,
      summary: datasetTitle(d.name, d.shape),
    })),
  );
  const refit = forgetFits(); // asked on the socket that closed: a mode change's is asked again
  const again = S.info && S.state && msg.datasets.some((d) => d.index === S.info.index);
  restore = again ? { state: S.state, zoom: S.zoom, point: S.selectedPoint, camera: S.initialCamera, refit } : null;
  const fromUrl = S.info ? null : fragmentSnapshot();
  if (fromUrl) urlLoad = loadSnapshot(fromUrl);
  // The page's own state follows a reopen (its data TF fitted as it was): no fit to replace.
  else if (again) send({ type: 'open', dataset: S.info.index, fit: false });
  else send({ type: 'open', dataset: 0 });
}

// A (T, Z, Y, X) shape's volume as x×y×z; `short`: a cube as n³.
function dims(shape, short = false) {
  const [z, y, x] = shape.slice(1);
  return short && x === y && y === z ? `${x}³` : `${x}×${y}×${z}`;
}

function datasetTitle(name, shape, dtype) {
  return `${name}: ${dims(shape)} voxels (x×y×z), ${shape[0]} steps${dtype ? `, ${dtype}` : ''}`;
}

function onDataset(msg) {
  if (!S.info || S.info.index !== msg.index) resetHistory();
  forgetFits(); // a fit asked before is for the state this replaces
  urlLoad = null;
  S.info = msg;
  S.state = msg.state;
  S.zoom = [0, 1];
  S.selectedPoint = Math.min(1, shown('data_tf').points.length - 1);
  S.initialCamera = { ...(msg.opening_camera || msg.state.camera) };
  if (!restore) S.fits = msg.fitted ? [msg.fitted] : []; // a data set opens fitted to its window
  if (restore) {
    // Every field the server describes, as the page had it before the socket closed.
    for (const k of Object.keys(msg.state)) if (k in restore.state) S.state[k] = restore.state[k];
    S.zoom = restore.zoom;
    S.selectedPoint = Math.min(restore.point, shown('data_tf').points.length - 1);
    if (restore.camera) S.initialCamera = restore.camera;
  }
  const restored = restore ? { ...S.state } : null;
  const refit = restore && restore.refit;
  restore = null;
  $('dataset').value = msg.index;
  const { t, z, y, x } = msg.shape;
  $('dataset').title = datasetTitle(msg.name, [t, z, y, x], msg.dtype);
  syncControls();
  syncShading();
  const size = layoutViews();
  update(Object.assign(restored || {}, { size, views: S.state.views }), 'full');
  if (refit) refitMode();
  drawTriads();
  drawTimeline();
  drawTF();
  clearProbe(); // the old voxel's curve does not belong on the new series' axis
  if (!restored) clearEvents(); // (a reconnect's list is cleared on its info: onInfo)
  showMark(null);
}

function onDownload(msg) {
  viewer.downloads.push(msg);
  const a = document.createElement('a');
  a.href = msg.url;
  a.download = msg.filename;
  page.shell.appendChild(a);
  a.click();
  a.remove();
  setStatus(`saved ${msg.filename}`);
}

// State set by the server's side (a notebook's code: w.mode = 'max'), already applied there: the
// page shows it (its controls, the timeline, the TF editor, the panels) without sending it
// back; a new number of views lays the panels out again and sends their size.
function onState(msg) {
  if (!S.state) return;
  const fields = msg.state;
  const views = fields.views && fields.views.length !== S.state.views.length;
  Object.assign(S.state, fields);
  S.selectedView = Math.min(S.selectedView, S.state.views.length - 1);
  S.selectedPoint = Math.min(S.selectedPoint, shown('data_tf').points.length - 1);
  if (views) update({ size: layoutViews(), views: S.state.views });
  else layoutViews();
  syncControls();
  syncShading();
  drawTriads();
  drawTimeline();
  drawTF();
}

function onText(msg) {
  switch (msg.type) {
    case 'info':
      onInfo(msg);
      break;
    case 'dataset':
      onDataset(msg);
      break;
    case 'histogram':
      if (S.info && msg.dataset !== S.info.index) break; // counted for the data set left
      tookHistogram(msg);
      noteHistogram();
      drawTF();
      break;
    case 'fit':
      onFit(msg);
      break;
    case 'slice':
      onSlice(msg);
      break;
    case 'probe':
      onProbe(msg);
      eventsProbed(msg);
      showMark(msg.values && msg.mark ? { view: msg.view, x: msg.mark[0], y: msg.mark[1] } : null);
      break;
    case 'progress':
      if (msg.what === 'refine') showRefineProgress(msg);
      else if (msg.what === 'frame') showFrameProgress(msg);
      else if (msg.what === 'events') eventsProgress(msg);
      else movieProgress(msg);
      break;
    case 'download':
      onDownload(msg);
      break;
    case 'events':
      onEvents(msg);
      break;
    case 'steps':
      onSteps(msg);
      break;
    case 'state':
      onState(msg);
      break;
    case 'error':
      movieProgress(null);
      if (msg.id !== null && msg.id >= viewer.sent) frameArrived(); // no frame will come
      viewer.errors.push(msg);
      fitFailed(msg.id);
      eventsFailed(msg.id);
      sliceFailed(msg);
      setStatus(`error: ${msg.message}`, true);
      if (urlLoad !== null && msg.id === urlLoad) {
        urlLoad = null; // the URL's snapshot does not fit: the default view instead
        send({ type: 'open', dataset: 0 });
      }
      break;
    default:
      break;
  }
}

// The panels follow the view area (window size, side panel shown or not) and the device
// pixel ratio (browser zoom fires 'resize'); the render size follows the pictures (which also
// change size when the legend or the axes are shown or hidden).
let resizeTimer = 0;
function relayout() {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(() => {
    if (!S.state) return;
    const size = layoutViews();
    if (size[0] !== S.state.size[0] || size[1] !== S.state.size[1]) update({ size });
    drawTimeline();
    drawTF();
    drawProbe();
    drawTrack();
    drawLegends();
  }, 150);
}

// Starts the viewer: `host` says where it lives (state.js: pageState; the page's defaults are
// the document's), `transport` what it talks over (connection.js). Returns the viewer
// (state.js: what the tests read) and `stop`, which stops it (a notebook widget's view
// removed): the transport closed, listeners and timers gone.
export function start(host, transport) {
  page = pageState(host);
  ({ S, viewer } = page);
  const observer = new ResizeObserver(relayout);
  window.addEventListener('resize', relayout);
  observer.observe($('views'));
  // A view selected (a click on its picture, a link toggled): the editors show what it is
  // drawn with, its own camera and TFs where it has them.
  bindViews(page, relayout, () => {
    S.selectedPoint = Math.min(S.selectedPoint, shown('data_tf').points.length - 1);
    syncControls();
    drawTF();
    drawTriads();
    drawTimeline(); // its row of the selected view's cells
    sliceFrame();
  });
  bindProbe(page);
  bindSlice(page);
  bindEvents(page);
  $('side-toggle').addEventListener('click', () => {
    const hidden = page.shell.classList.toggle('side-hidden');
    $('side-toggle').textContent = hidden ? 'panel ◂' : 'panel ▸';
    $('side-toggle').setAttribute('aria-expanded', String(!hidden));
  });

  bindTimeline(page);
  bindTF(page);
  bindFit(page);
  bindControls(page);
  bindShading(page);
  bindOrientation(page);
  bindKeys(page);
  bindHistory(page);
  bindSnapshot(page);
  bindLegend(page);
  bindTimeFollow(page);
  connect(
    page,
    {
      onText,
      onFrame: (buf) => {
        onFrame(buf);
        noteFocus();
        sliceFrame();
      },
    },
    transport,
  );
  const stop = () => {
    disconnect();
    unbindKeys();
    observer.disconnect();
    window.removeEventListener('resize', relayout);
    clearTimeout(resizeTimer);
  };
  return { viewer, stop };
}
