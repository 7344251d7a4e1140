// The connection to the server, through a transport: the page's WebSocket (`socketTransport`,
// opened again after it closes: backoff, status shown) or a notebook widget's comm
// (`modelTransport`: an anywidget model, frames as binary buffers). The server renders the
// newest state only, so the page may send freely; it still coalesces input to one update
// message per animation frame. While a frame is awaited for longer than BUSY_AFTER_MS (a large
// window's steps are read, a mode's first use builds its kernels) the #busy indicator says so,
// with the latest stage the server reported of it ('reading steps 3/10', 'integrating',
// 'recolouring', 'drawing') and the time waited.
//
// A transport is { open(callbacks), send(text), isOpen(), retries, close() }: `open` starts it
// and calls callbacks.onOpen(), callbacks.onMessage(text or ArrayBuffer) for each message from
// the server (a binary one is a frame) and callbacks.onClose() when it ends; `retries`: it is
// opened again after it closed.

import { $, setStatus } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to connect.
let S;
let viewer;
let shell;

const BUSY_AFTER_MS = 400;
let waitingSince = null; // when the oldest update not yet answered by a frame was sent
let busyTimer = 0;

let transport = null;
let nextId = 1;
export const sentAt = new Map(); // request id -> when it was sent (for round trips)

// The page's socket, /ws on the page's host with the address's token (dropped from the
// address bar: the cookie keeps us in).
export function socketTransport() {
  const params = new URLSearchParams(location.search);
  const token = params.get('token') || '';
  if (token) history.replaceState(null, '', location.pathname + location.hash);
  let ws = null;
  return {
    retries: true,
    open({ onOpen, onMessage, onClose }) {
      const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
      const q = token ? `?token=${encodeURIComponent(token)}` : '';
      ws = new WebSocket(`${proto}//${location.host}/ws${q}`);
      ws.binaryType = 'arraybuffer';
      ws.onopen = onOpen;
      ws.onmessage = (e) => onMessage(e.data);
      ws.onclose = onClose;
    },
    send: (text) => ws.send(text),
    isOpen: () => !!ws && ws.readyState === WebSocket.OPEN,
    close: () => ws && ws.close(),
  };
}

// A buffer of a comm message (a DataView, or an ArrayBuffer) as an ArrayBuffer of its bytes.
const arrayBuffer = (b) =>
  b instanceof ArrayBuffer ? b : b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);

// A notebook widget's comm (chronocl/notebook): an anywidget model's custom messages. The
// page's messages go as {text}; the kernel's come as {text}, {frame: 1} with the frame as a
// buffer, or {download} with the file as a buffer (shown to the page as a download message
// whose url is the file's blob URL). {type: 'hello'} asks the kernel for its `info` message.
export function modelTransport(model) {
  let handler = null;
  const urls = [];
  return {
    retries: false,
    open({ onOpen, onMessage }) {
      handler = (msg, buffers) => {
        if (!msg || typeof msg !== 'object') return;
        if (msg.frame && buffers && buffers.length) onMessage(arrayBuffer(buffers[0]));
        else if (typeof msg.text === 'string') onMessage(msg.text);
        else if (msg.download && buffers && buffers.length) {
          const d = JSON.parse(msg.download);
          const url = URL.createObjectURL(new Blob([arrayBuffer(buffers[0])], { type: d.media_type }));
          urls.push(url);
          if (urls.length > 16) URL.revokeObjectURL(urls.shift());
          onMessage(JSON.stringify({ ...d, url }));
        }
      };
      model.on('msg:custom', handler);
      onOpen();
      model.send({ type: 'hello' });
    },
    send: (text) => model.send({ text }),
    isOpen: () => handler !== null,
    close() {
      if (handler) model.off('msg:custom', handler);
      handler = null;
      for (const url of urls.splice(0)) URL.revokeObjectURL(url);
    },
  };
}

// Opens the transport; text messages go to onText(parsed JSON), binary frames to onFrame. When a
// socket closes (the server stopped or restarted, the network dropped) it is opened again after
// a growing pause (RETRY_MS, then its last value over and over), the wait shown in the status
// line; the page then sends its state back (app.js), so the view returns as it was.
const RETRY_MS = [500, 1000, 2000, 4000, 8000];
let handlers = null;
let attempt = 0;
let retryTimer = 0;
let stopped = false;

export function connect(page, h, t) {
  ({ S, viewer, shell } = page);
  handlers = h;
  transport = t;
  open();
}

// The connection closed for good and its timers stopped (a notebook widget's view removed).
export function disconnect() {
  stopped = true;
  clearTimeout(retryTimer);
  clearTimeout(settleTimer);
  clearInterval(busyTimer);
  if (transport) transport.close();
}

function open() {
  transport.open({
    onOpen: () => {
      attempt = 0;
      viewer.connects += 1;
      shell.dataset.connection = 'open';
      if (viewer.connects > 1) setStatus('reconnected: restoring the view…');
    },
    onMessage: (data) =>
      typeof data === 'string' ? handlers.onText(JSON.parse(data)) : handlers.onFrame(data),
    onClose: () => {
      frameArrived(); // nothing more will come on this socket
      viewer.sent = 0; // request ids start again on the next socket's frames
      if (stopped || !transport.retries) return;
      const wait = RETRY_MS[Math.min(attempt, RETRY_MS.length - 1)];
      attempt += 1;
      const hint = attempt > RETRY_MS.length ? ' (restarted with another token? open the URL it printed)' : '';
      setStatus(`disconnected: server unreachable; reconnecting in ${(wait / 1000).toFixed(1)} s (attempt ${attempt})${hint}`, true);
      shell.dataset.connection = 'retrying';
      clearTimeout(retryTimer);
      retryTimer = setTimeout(open, wait);
    },
  });
}

export const connected = () => !!transport && transport.isOpen();

export function send(msg) {
  if (!connected()) return 0;
  msg.id = nextId++;
  sentAt.set(msg.id, performance.now());
  if (sentAt.size > 200) sentAt.delete(sentAt.keys().next().value);
  transport.send(JSON.stringify(msg));
  return msg.id;
}

// Updates are merged into S.state at once and sent once per animation frame; each is told to
// the function given to `onEdited` (history.js: undo history, URL fragment), with `merge`: the
// update completes the last edit (a mode change's refit, fit.js) rather than being one itself.
let edited = null;
export function onEdited(fn) {
  edited = fn;
}
let pending = null;
let pendingQuality = 'full';
// `view`: the view whose camera, data TF or time TF the fields edit (default: the selected
// one); where it has its own (unlinked) they go to its own copy, in `views`, else to the shared.
export function update(fields, quality = 'full', merge = false, view = S.selectedView) {
  fields = routed(fields, view);
  pending = Object.assign(pending || {}, fields);
  pendingQuality = quality;
  Object.assign(S.state, fields);
  if (edited) edited(quality, merge);
  requestAnimationFrame(flushUpdates);
}

// What a view may have of its own instead of the shared one (null in its entry: linked).
export const LINKABLE = ['camera', 'data_tf', 'time_tf'];

// The camera, data TF or time TF (`key`) view `i` (default: the selected one) is drawn with: its
// own where it is unlinked, else the shared one. The editors and drags read and edit this one.
export function shown(key, i = S.selectedView) {
  const v = S.state.views[i];
  return (v && v[key]) || S.state[key];
}

// `fields` with a camera, data TF or time TF for `view` moved into its entry of `views` where
// the view has its own of it (the other views as they are). Fields that give `views` give the
// whole state (undo, a snapshot, a reconnect): their camera and TFs are the shared ones.
function routed(fields, view) {
  const v = S.state && S.state.views[view];
  const own = LINKABLE.filter((k) => k in fields && v && v[k]);
  if (!own.length || 'views' in fields) return fields;
  const out = { ...fields };
  const views = S.state.views.map((x) => ({ ...x }));
  for (const k of own) {
    views[view][k] = out[k];
    delete out[k];
  }
  out.views = views;
  return out;
}

// Send the pending update now (it goes once per animation frame): a request the render thread
// answers from the state it drew (slice.js) must not overtake the update before it.
export function flushUpdates() {
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

// The latest stage the server reported of the frame awaited (a `progress` message of what
// 'frame'): { stage, done, total }, or null before the first.
let busyStage = null;

// Each stage's pieces, as the busy box counts them.
const PIECES = { 'reading steps': '', integrating: ' slabs', sliding: ' parts' };

// The busy box's words for a stage: its name and how far it got ('reading steps 3/10',
// 'integrating 2/8 slabs'), or its name alone: 'recolouring' (a TF edit's winners gathered,
// counted in rows and then phases: no count that reads well) and 'drawing' (draw, encode, send).
export function stageText(p) {
  if (p.stage === 'preparing the recolouring') return 'recolouring';
  if (p.stage === 'drawing' || !(p.total > 1)) return p.stage; // one piece: nothing to count
  return `${p.stage} ${p.done}/${p.total}${PIECES[p.stage] ?? ''}`;
}

// How far the frame awaited got: the busy box says its latest stage (shown once the wait is
// longer than BUSY_AFTER_MS).
export function showFrameProgress(msg) {
  if (waitingSince === null) return; // its frame came already
  busyStage = msg;
  showBusy();
}

function showBusy() {
  const el = $('busy');
  const waited = waitingSince === null ? 0 : performance.now() - waitingSince;
  el.hidden = waited < BUSY_AFTER_MS;
  if (!el.hidden) {
    // Before the server's first report (a mode's first use builds its kernels, a frame waits
    // for another's) it says only how long it has waited.
    const what = busyStage ? stageText(busyStage) : 'working';
    el.textContent = `${what}… ${(waited / 1000).toFixed(1)} s`;
    el.title = busyStage ? `the frame awaited: ${what}` : "the frame awaited: not started yet, or building a mode's kernels";
  }
}

// A frame (or an error) answering the newest update arrived.
export function frameArrived() {
  waitingSince = null;
  busyStage = null;
  clearInterval(busyTimer);
  $('busy').hidden = true;
}

// A full-quality frame once input has paused for `ms`.
let settleTimer = 0;
export function settleLater(ms = 250) {
  clearTimeout(settleTimer);
  settleTimer = setTimeout(() => update({}, 'full'), ms);
}
