// Fit to window: the data TF's value range fitted to the selected view's window and mode, as
// the command line fits it (the server's `fit` reply: chronocl/viewer/fit.py). The curve keeps
// its shape over u in [0, 1] and takes the fitted range: the editor draws it over the series'
// range between the fitted lo and hi (tf_editor.js), flat beyond them. Fitting again (another
// window, another mode) gives the same curve the new range, so nothing is squeezed twice; the
// fit is one edit, undone as any TF edit is.
//
// A data set opens fitted (the server fits its first window and view's mode); while the curve
// is still the default one (its opacity, whatever its colours: the command line's rule), a
// change of the first view's mode fits again. The mode goes to the server at once, as any
// edit; the fit follows when its reply comes (the server reads a sample of the window for it,
// which can take seconds) and sends the data TF alone, so edits made meanwhile stand. It joins
// the mode change's undo step where nothing else was edited in between (else it is a step of
// its own), and is dropped where the curve or the first view's mode changed meanwhile (asked
// again after a reconnect that lost it). A curve edited by hand is fitted only by the button.
// "series range" spreads the curve over the series' whole range as it is drawn, so points can
// go beyond the fitted range.

import { send, shown, update } from './connection.js';
import { $, setStatus } from './state.js';
import { dataTF, drawTF, handles, interp, noteRange, setHandles, syncPointColor, toSeries } from './tf_editor.js';

// The page's state (state.js: pageState), made by app.js and given to bindFit.
let S;
let viewer;

// Fit request id -> {auto: a mode change's refit, commits: edits committed when it was asked}.
const waits = new Map();

// Forget the fits asked (on a socket that closed, for a state replaced): their replies are
// not applied. Returns whether a mode change's refit was among them.
export function forgetFits() {
  const auto = [...waits.values()].some((w) => w.auto);
  waits.clear();
  return auto;
}

// Whether `pts` has the default curve's opacity (sampled as `DataTF.range_kind` does).
export function isDefaultCurve(pts) {
  const d = S.choices.data_tf_default;
  for (let k = 0; k <= 256; k++) {
    if (Math.abs(interp(pts, k / 256, 4) - interp(d, k / 256, 4)) > 1e-9) return false;
  }
  return true;
}

// Ask for the range of `view`'s window for `mode` (null: the view's); sent after the update
// pending this frame (the window, a mode change), so the server fits the state the page shows.
function requestFit(view, mode, auto) {
  if (!S.info) return;
  const commits = viewer.history.commits; // the mode change's commit, for an auto fit
  requestAnimationFrame(() => {
    const id = send({ type: 'fit', view, ...(mode ? { mode } : {}) });
    if (id) waits.set(id, { auto, commits });
  });
}

// The button and the F key: the selected view's window and mode.
export const fitToWindow = () => requestFit(S.selectedView, null, false);

// The default curve fitted again to the first view's mode (after a mode change; after a
// reconnect that lost the reply, once the page's state is restored).
export function refitMode() {
  if (isDefaultCurve(shown('data_tf', 0).points)) requestFit(0, S.state.views[0].mode, true);
}

// A change of a view's mode (`views`: every view, the new mode in): sent at once, then the
// first view's refitted.
export function modeChanged(view, views) {
  update({ views });
  noteRange(); // the fit's note says whether the curve is still fitted to what is shown
  if (view === 0) refitMode();
}

export function onFit(msg) {
  const w = waits.get(msg.id);
  if (!w) return;
  waits.delete(msg.id);
  if (w.auto && !(S.state.views[0].mode === msg.mode && isDefaultCurve(shown('data_tf', 0).points))) {
    return; // the mode changed again (its own fit follows) or the curve was edited
  }
  S.fits.push({ range: msg.range, window: msg.window, mode: msg.mode });
  if (S.fits.length > 50) S.fits.shift();
  // A refit with no edit since its mode change: in that change's undo step.
  const merge = w.auto && viewer.history.commits === w.commits;
  // the fitted view's data TF: its own where it has one, else the shared one
  const fitted = { data_tf: dataTF(shown('data_tf', msg.view).points, msg.range) };
  update(fitted, 'full', merge, msg.view);
  syncPointColor();
  drawTF();
  if (!w.auto) setStatus(`data TF fitted to view ${msg.view + 1} (${msg.mode}, window ${msg.window.slice(0, 2).join(':')})`);
}

// An error answering a fit: the fit is not applied (the error is shown).
export function fitFailed(id) {
  waits.delete(id);
}

// The curve over the series' range, drawn where it was: each point (under a colour map, each
// handle, the map then spanning the series' range) at its place on the axis, and flat ends at
// the series' ends (a range a snapshot gave beyond the series' is cut there).
export function spreadToSeries() {
  if (!S.state || !shown('data_tf').value_range) return;
  const pts = shown('data_tf').points;
  const { map, idx } = handles(pts);
  const own = map ? idx.map((i) => [pts[i][0], pts[i][4]]) : pts.map((p) => p.slice());
  const moved = own.map((q) => [toSeries(q[0]), ...q.slice(1)]);
  const at = (g) => [g, ...moved[0].slice(1).map((_, j) => interp(moved, g, j + 1))];
  const spread = [at(0), ...moved.filter((q) => q[0] > 1e-9 && q[0] < 1 - 1e-9), at(1)];
  if (!setHandles(spread, map, 0)) return;
  shown('data_tf').value_range = null;
  syncPointColor();
  update({ data_tf: dataTF(shown('data_tf').points, null) }, 'full');
  drawTF();
}

export function bindFit(page) {
  ({ S, viewer } = page);
  $('tf-fit').addEventListener('click', fitToWindow);
  $('tf-unfit').addEventListener('click', spreadToSeries);
}
