// The page's undo history: undo / redo of every edit, over the committed state kept as a
// snapshot (snapshot.js: the saved state, the URL fragment that carries it, Save / Load
// session).
//
// An edit is an update sent at full quality (the end of a drag, a menu choice, a key): its
// state is committed, the one before it goes on the undo list (HISTORY at most), and the
// fragment is rewritten. Preview updates during a drag are not commits; the drag's end is.
// Play's slides move the committed state along without becoming edits.
//
// The committed state holds `focus` too, the world box the views frame; frames report it
// (S.focus), and the committed state takes it when it changes (`noteFocus`).

import { onEdited, shown, update } from './connection.js';
import { syncControls } from './controls.js';
import { drawTriads } from './orientation.js';
import { FIELDS, snapshot, writeFragment } from './snapshot.js';
import { $, setStatus } from './state.js';
import { drawTF } from './tf_editor.js';
import { drawTimeline } from './timeline.js';
import { layoutViews } from './views.js';

// The page's state (state.js: pageState), made by app.js and given to bindHistory.
let S;
let viewer;

const HISTORY = 100;

const undoList = [];
const redoList = [];
let committed = null; // JSON text of the committed snapshot
let applying = false;

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

export function bindHistory(page) {
  ({ S, viewer } = page);
  viewer.history = { undo: 0, redo: 0, commits: 0 };
  onEdited(edited);
  $('undo').addEventListener('click', undo);
  $('redo').addEventListener('click', redo);
  showCounts();
}
