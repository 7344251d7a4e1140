// The keyboard shortcuts: one table, SHORTCUTS, that both binds the keys (the page's only
// keydown handler) and fills the list `?` opens, so the list cannot miss a key the page binds.
// Keys are ignored while typing in a field (where Ctrl+Z is the field's own undo) and when
// Alt is held; entries marked `ctrl` need Ctrl (or Meta), the others act without it.

import { fitToWindow } from './fit.js';
import { redo, undo } from './history.js';
import { toggleLegend } from './legend.js';
import { resetCamera, standardView, toggleTriad } from './orientation.js';
import { $ } from './state.js';
import { play, scalePlaySpeed, setPlayMode, slide, togglePlaying } from './timeline.js';
import { cancelRefine } from './views.js';

// The page's state (state.js: pageState), made by app.js and given to bindKeys.
let S;
let viewer;
let listening = null; // [target, handler] of the keydown listener, for unbindKeys

// keys: KeyboardEvent.key values; label: how the list shows them.
export const SHORTCUTS = [
  { keys: [' '], label: 'Space', does: 'play / pause', run: togglePlaying },
  { keys: ['ArrowRight'], label: '→', does: 'slide the window one stride later', run: () => slide(1) },
  { keys: ['ArrowLeft'], label: '←', does: 'slide the window one stride earlier', run: () => slide(-1) },
  { keys: ['+', '='], label: '+', does: 'play faster (×1.5 steps/s)', run: () => scalePlaySpeed(1.5) },
  { keys: ['-', '_'], label: '−', does: 'play slower (÷1.5 steps/s)', run: () => scalePlaySpeed(1 / 1.5) },
  {
    keys: ['b'],
    label: 'B',
    does: 'play mode: loop ↔ bounce',
    run: () => setPlayMode(play.mode === 'loop' ? 'bounce' : 'loop'),
  },
  { keys: ['r'], label: 'R', does: 'reset the camera', run: resetCamera },
  { keys: ['x'], label: 'X', does: 'look along +X', run: () => standardView('+x') },
  { keys: ['X'], label: 'Shift+X', does: 'look along −X', run: () => standardView('-x') },
  { keys: ['y'], label: 'Y', does: 'look along +Y', run: () => standardView('+y') },
  { keys: ['Y'], label: 'Shift+Y', does: 'look along −Y', run: () => standardView('-y') },
  { keys: ['z'], label: 'Z', does: 'look along +Z', run: () => standardView('+z') },
  { keys: ['Z'], label: 'Shift+Z', does: 'look along −Z (the front view with up y)', run: () => standardView('-z') },
  { keys: ['a'], label: 'A', does: 'show / hide the axes triads', run: toggleTriad },
  { keys: ['l'], label: 'L', does: 'show / hide the time legends', run: () => toggleLegend() },
  { keys: ['f'], label: 'F', does: "fit the data TF's range to the selected view's window and mode", run: fitToWindow },
  { keys: ['z'], ctrl: true, label: 'Ctrl+Z', does: 'undo the last edit', run: undo },
  { keys: ['Z', 'y'], ctrl: true, label: 'Ctrl+Shift+Z, Ctrl+Y', does: 'redo the edit undone', run: redo },
  { keys: ['?'], label: '?', does: 'show / hide this list', run: () => showHelp($('help').hidden) },
  {
    keys: ['Escape'],
    label: 'Esc',
    does: 'close this list; stop refining to full resolution',
    run: () => {
      showHelp(false);
      cancelRefine();
    },
    always: true,
  },
];

const TEXT_FIELDS = 'textarea, input:not([type=checkbox]):not([type=range]):not([type=file])';

export function showHelp(on) {
  $('help').hidden = !on;
  $('help-toggle').setAttribute('aria-expanded', String(on));
}

function fillHelp() {
  const rows = SHORTCUTS.map((s) => {
    const tr = document.createElement('tr');
    const k = document.createElement('td');
    const kbd = document.createElement('kbd');
    kbd.textContent = s.label;
    k.appendChild(kbd);
    const d = document.createElement('td');
    d.textContent = s.does;
    tr.append(k, d);
    tr.dataset.keys = s.keys.join(' ');
    return tr;
  });
  $('help-keys').replaceChildren(...rows);
}

export function bindKeys(page) {
  ({ S, viewer } = page);
  viewer.shortcuts = SHORTCUTS.map((s) => ({ keys: s.keys, ctrl: !!s.ctrl, label: s.label, does: s.does }));
  fillHelp();
  const byKey = new Map();
  const byCtrlKey = new Map();
  for (const s of SHORTCUTS) for (const k of s.keys) (s.ctrl ? byCtrlKey : byKey).set(k, s);
  const onKey = (e) => {
    if (e.altKey || e.defaultPrevented) return; // (a key a control took: a list row's Space)
    const ctrl = e.ctrlKey || e.metaKey;
    // Menus and checkboxes have no undo of their own: Ctrl+Z there is the page's.
    const field = ctrl ? TEXT_FIELDS : 'input, select, textarea';
    if (e.target.closest && e.target.closest(field)) return;
    const s = (ctrl ? byCtrlKey : byKey).get(e.key);
    if (!s || (!S.info && !s.always && s.keys[0] !== '?')) return;
    s.run();
    e.preventDefault();
  };
  // The page's keys: the document's; a notebook widget's: its own element's (page.keys).
  page.keys.addEventListener('keydown', onKey);
  listening = [page.keys, onKey];
  $('help-toggle').addEventListener('click', () => showHelp($('help').hidden));
  $('help-close').addEventListener('click', () => showHelp(false));
}

// The keys let go (a notebook widget removed from its cell).
export function unbindKeys() {
  if (listening) listening[0].removeEventListener('keydown', listening[1]);
  listening = null;
}
