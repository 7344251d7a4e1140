// The WebSocket to the server, opened again after it closes (backoff, status shown). The server
// renders the newest state only, so the page may send freely; it still coalesces input to one
// update message per animation frame. While a frame
// is awaited for longer than BUSY_AFTER_MS (a large window's steps are read, a mode's first use
// builds its kernels) the #busy indicator says so, with the time waited.

import { $, setStatus } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to connect.
let S;
let viewer;

const BUSY_AFTER_MS = 400;
let waitingSince = null; // when the oldest update not yet answered by a frame was sent
let busyTimer = 0;

const params = new URLSearchParams(location.search);
const token = params.get('token') || '';
if (token) history.replaceState(null, '', location.pathname + location.hash); // the cookie keeps us in

let ws = null;
let nextId = 1;
export const sentAt = new Map(); // request id -> when it was sent (for round trips)

// Opens the socket; text messages go to onText(parsed JSON), binary frames to onFrame. When it
// closes (the server stopped or restarted, the network dropped) it is opened again after a
// growing pause (RETRY_MS, then its last value over and over), the wait shown in the status
// line; the page then sends its state back (app.js), so the view returns as it was.
const RETRY_MS = [500, 1000, 2000, 4000, 8000];
let handlers = null;
let attempt = 0;
let retryTimer = 0;

export function connect(page, h) {
  ({ S, viewer } = page);
  handlers = h;
  open();
}

function open() {
  const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
  const q = token ? `?token=${encodeURIComponent(token)}` : '';
  ws = new WebSocket(`${proto}//${location.host}/ws${q}`);
  ws.binaryType = 'arraybuffer';
  ws.onopen = () => {
    attempt = 0;
    viewer.connects += 1;
    document.body.dataset.connection = 'open';
    if (viewer.connects > 1) setStatus('reconnected: restoring the view…');
  };
  ws.onmessage = (e) =>
    typeof e.data === 'string' ? handlers.onText(JSON.parse(e.data)) : handlers.onFrame(e.data);
  ws.onclose = () => {
    frameArrived(); // nothing more will come on this socket
    viewer.sent = 0; // request ids start again on the next socket's frames
    const wait = RETRY_MS[Math.min(attempt, RETRY_MS.length - 1)];
    attempt += 1;
    const hint = attempt > RETRY_MS.length ? ' (restarted with another token? open the URL it printed)' : '';
    setStatus(`disconnected: server unreachable; reconnecting in ${(wait / 1000).toFixed(1)} s (attempt ${attempt})${hint}`, true);
    document.body.dataset.connection = 'retrying';
    clearTimeout(retryTimer);
    retryTimer = setTimeout(open, wait);
  };
}

export const connected = () => !!ws && ws.readyState === WebSocket.OPEN;

export function send(msg) {
  if (!ws || ws.readyState !== WebSocket.OPEN) return 0;
  msg.id = nextId++;
  sentAt.set(msg.id, performance.now());
  if (sentAt.size > 200) sentAt.delete(sentAt.keys().next().value);
  ws.send(JSON.stringify(msg));
  return msg.id;
}

// Updates are merged into S.state at once and sent once per animation frame; each is told to
// the function given to `onEdited` (session.js: undo history, URL fragment), with `merge`: the
// update completes the last edit (a mode change's refit, fit.js) rather than being one itself.
let edited = null;
export function onEdited(fn) {
  edited = fn;
}
let pending = null;
let pendingQuality = 'full';
export function update(fields, quality = 'full', merge = false) {
  pending = Object.assign(pending || {}, fields);
  pendingQuality = quality;
  Object.assign(S.state, fields);
  if (edited) edited(quality, merge);
  requestAnimationFrame(flush);
}

function flush() {
  if (!pending) return;
  const msg = Object.assign({ type: 'update', quality: pendingQuality }, pending);
  pending = null;
  viewer.sent = send(msg);
  if (viewer.sent && waitingSince === null) {
    waitingSince = performance.now();
    clearInterval(busyTimer);
    busyTimer = setInterval(showBusy, 100);
  }
}

function showBusy() {
  const el = $('busy');
  const waited = waitingSince === null ? 0 : performance.now() - waitingSince;
  el.hidden = waited < BUSY_AFTER_MS;
  if (!el.hidden) {
    // The server does not say which part takes the time; name them all rather than guess one.
    el.textContent = `working… ${(waited / 1000).toFixed(1)} s (reading the window's steps, building a new mode's kernels, integrating, drawing)`;
  }
}

// A frame (or an error) answering the newest update arrived.
export function frameArrived() {
  waitingSince = null;
  clearInterval(busyTimer);
  $('busy').hidden = true;
}

// A full-quality frame once input has paused for `ms`.
let settleTimer = 0;
export function settleLater(ms = 250) {
  clearTimeout(settleTimer);
  settleTimer = setTimeout(() => update({}, 'full'), ms);
}
