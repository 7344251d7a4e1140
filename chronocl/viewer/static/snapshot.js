// The snapshot: the page's state saved as one object in the server's snapshot format
// (chronocl/viewer/snapshot.py; the server checks it), which users know as a session file: the
// page's state fields with the format's version and the data set's name. The panel size is
// left out: it follows the page's layout, and resizing is no edit. This module makes it
// (`snapshot`), carries it in the URL fragment (#state=...), and saves and loads it (Save /
// Load session). The undo history of committed snapshots is history.js. The file format keeps
// its "session" names (the chronocl_session key, the save message's what: 'session'), so files
// saved before still load.
//
// A snapshot also holds `focus`, the world box the views frame (the server frames the visible
// region of a data set's first frame and of the frame after a camera reset); frames report it
// (S.focus), and the committed state takes it when it changes (history.js: `noteFocus`).

import { send } from './connection.js';
import { $, setStatus } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindSnapshot.
let S;

const VERSION = 1;
// The state fields a snapshot holds (history.js restores them).
export const FIELDS = ['window', 'views', 'camera', 'data_tf', 'time_tf', 'enhance', 'threshold', 'clip', 'background', 'outline', 'shading'];

let useFragment = true; // the address's #state= carries the state (not in a notebook widget)

// The page's state as a snapshot object.
export function snapshot() {
  const s = { chronocl_session: VERSION, dataset: { name: S.info.name } };
  for (const k of FIELDS) if (k in S.state) s[k] = S.state[k];
  s.focus = S.focus || null;
  return s;
}

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

// The committed snapshot's JSON `text` written to the address (#state=...).
export function writeFragment(text) {
  if (!useFragment) return;
  history.replaceState(null, '', `${location.pathname}${location.search}#state=${toBase64Url(text)}`);
}

// The snapshot the page was opened with (#state=...), or null; a fragment that does not
// decode is reported and ignored.
export function fragmentSnapshot() {
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
// A snapshot sent to the server (the load message's `session`), which answers as it answers
// `open` (or with an error, and the page keeps what it shows). Returns the request id.
export function loadSnapshot(snapshot) {
  const s = { ...snapshot };
  delete s.size; // the panels' size is the page's
  return send({ type: 'load', session: s });
}

export function bindSnapshot(page) {
  ({ S } = page);
  useFragment = page.fragment;
  $('save-session').addEventListener('click', () => send({ type: 'save', what: 'session' }));
  $('load-session').addEventListener('click', () => $('session-file').click());
  $('session-file').addEventListener('change', async () => {
    const file = $('session-file').files[0];
    $('session-file').value = '';
    if (!file) return;
    let snapshot;
    try {
      snapshot = JSON.parse(await file.text());
    } catch {
      setStatus(`error: ${file.name} is not JSON; choose a session saved with Save session`, true);
      return;
    }
    loadSnapshot(snapshot);
    setStatus(`loading ${file.name}…`);
  });
}
