// The state the page keeps: undo / redo of every edit, the URL fragment that carries the
// state (#state=...), and Save / Load session. All three use the server's session format
// (chronocl/viewer/session_file.py; the server checks it): a session object is the page's
// state fields with the format's version and the data set's name. The panel size is left
// out: it follows the page's layout, and resizing is no edit.
//
// An edit is an update sent at full quality (the end of a drag, a menu choice, a key): its
// state is committed, the one before it goes on the undo list (HISTORY at most), and the
// fragment is rewritten. Preview updates during a drag are not commits; the drag's end is.
// Play's slides move the committed state along without becoming edits.
//
// A session also holds `focus`, the world box the views frame (the server frames the visible
// region of a data set's first frame and of the frame after a camera reset); frames report it
// (S.focus), and the committed state takes it when it changes (`noteFocus`).

import { onEdited, send, shown, update } from './connection.js';
import { syncControls } from './controls.js';
import { drawTriads } from './orientation.js';
import { $, setStatus } from './state.js';
import { drawTF } from './tf_editor.js';
import { drawTimeline } from './timeline.js';
import { layoutViews } from './views.js';

// The page's state (state.js: pageState), made by app.js and given to bindSession.
let S;
let viewer;

const VERSION = 1;
const HISTORY = 100;
const FIELDS = ['window', 'views', 'camera', 'data_tf', 'time_tf', 'enhance', 'threshold', 'clip', 'background', 'outline', 'shading'];

const undoList = [];
const redoList = [];
let committed = null; // JSON text of the committed session
let useFragment = true; // the address's #state= carries the state (not in a notebook widget)
let applying = false;

// The page's state as a session object.
export function snapshot() {
  const s = { chronocl_session: VERSION, dataset: { name: S.info.name } };
  for (const k of FIELDS) if (k in S.state) s[k] = S.state[k];
  s.focus = S.focus || null;
  return s;
}

function showCounts() {
  viewer.history.undo = undoList.length;
  viewer.history.redo = redoList.length;
  $('undo').disabled = !undoList.length;
  $('redo').disabled = !redoList.length;
}

// A new data set: nothing to undo into (its first state becomes the committed one).
export function resetHistory() {
  undoList.length = 0;
  redoList.length = 0;
  committed = null;
  showCounts();
}

// `merge`: the edit completes the committed one (a mode change's refit), one undo step with it.
function edited(quality, merge) {
  if (applying || quality !== 'full' || !S.info) return;
  const text = JSON.stringify(snapshot());
  if (text === committed) return;
  if (committed !== null && !S.playing && !merge) {
    undoList.push(committed);
    if (undoList.length > HISTORY) undoList.shift();
    redoList.length = 0;
  }
  committed = text;
  viewer.history.commits += 1;
  writeFragment(text);
  showCounts();
}

// The committed state `text` shown again (undo, redo): one update with every field.
function restore(text) {
  const s = JSON.parse(text);
  const fields = {};
  for (const k of FIELDS) fields[k] = s[k];
  if (s.focus) fields.focus = s.focus; // the framing as it was
  applying = true;
  try {
    Object.assign(S.state, fields);
    S.selectedView = Math.min(S.selectedView, S.state.views.length - 1);
    S.selectedPoint = Math.min(S.selectedPoint, shown('data_tf').points.length - 1);
    update(Object.assign(fields, { size: layoutViews() }), 'full');
    delete S.state.focus; // a request, not part of the page's state
  } finally {
    applying = false;
  }
  committed = text;
  writeFragment(text);
  showCounts();
  syncControls();
  drawTF();
  drawTimeline();
  drawTriads();
}

function step(from, to, what) {
  if (!S.info || !from.length || committed === null) return;
  to.push(committed);
  restore(from.pop());
  setStatus(`${what}: ${from.length} more`);
}

// A frame framing another box than the committed state says: the committed state frames it
// (it changes only with the edit or the data set that was committed last).
export function noteFocus() {
  if (committed === null || applying) return;
  const s = JSON.parse(committed);
  const focus = S.focus || null;
  if (JSON.stringify(s.focus || null) === JSON.stringify(focus)) return;
  s.focus = focus;
  committed = JSON.stringify(s);
  writeFragment(committed);
}

export const undo = () => step(undoList, redoList, 'undone');
export const redo = () => step(redoList, undoList, 'redone');

// ------------------------------------------------------------------ the URL fragment
const toBase64Url = (text) => {
  const bytes = new TextEncoder().encode(text);
  let bin = '';
  for (const b of bytes) bin += String.fromCharCode(b);
  return btoa(bin).replace(/\+/g, '-').replace(/\//g, '_').replace(/=+$/, '');
};

const fromBase64Url = (code) => {
  const bin = atob(code.replace(/-/g, '+').replace(/_/g, '/'));
  return new TextDecoder().decode(Uint8Array.from(bin, (c) => c.charCodeAt(0)));
};

function writeFragment(text) {
  if (!useFragment) return;
  history.replaceState(null, '', `${location.pathname}${location.search}#state=${toBase64Url(text)}`);
}

// The session the page was opened with (#state=...), or null; a fragment that does not
// decode is reported and ignored.
export function fragmentSession() {
  if (!useFragment) return null;
  const m = /^#state=([A-Za-z0-9_-]+)$/.exec(location.hash);
  if (!m) return null;
  try {
    return JSON.parse(fromBase64Url(m[1]));
  } catch {
    setStatus('the URL\'s #state= does not decode; opening the default view', true);
    return null;
  }
}

// ------------------------------------------------------------------ save and load
// A session sent to the server, which answers as it answers `open` (or with an error, and
// the page keeps what it shows). Returns the request id.
export function loadSession(session) {
  const s = { ...session };
  delete s.size; // the panels' size is the page's
  return send({ type: 'load', session: s });
}

export function bindSession(page) {
  ({ S, viewer } = page);
  useFragment = page.fragment;
  viewer.history = { undo: 0, redo: 0, commits: 0 };
  onEdited(edited);
  $('undo').addEventListener('click', undo);
  $('redo').addEventListener('click', redo);
  $('save-session').addEventListener('click', () => send({ type: 'save', what: 'session' }));
  $('load-session').addEventListener('click', () => $('session-file').click());
  $('session-file').addEventListener('change', async () => {
    const file = $('session-file').files[0];
    $('session-file').value = '';
    if (!file) return;
    let session;
    try {
      session = JSON.parse(await file.text());
    } catch {
      setStatus(`error: ${file.name} is not JSON; choose a session saved with Save session`, true);
      return;
    }
    loadSession(session);
    setStatus(`loading ${file.name}…`);
  });
  showCounts();
}
