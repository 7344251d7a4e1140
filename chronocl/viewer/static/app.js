// chronocl viewer page: sends state changes over a WebSocket, shows the frames the server
// renders. Plain ES modules, no build step, no dependencies. This module routes the server's
// text messages and wires the parts together:
//   state.js       what the page shows (S, window.viewer) and small helpers
//   connection.js  the socket: send, coalesced updates
//   views.js       the view panels, orbit/zoom/probe input, incoming frames
//   timeline.js    the window brush, play, arrow keys
//   tf_editor.js   the data transfer function editor
//   probe.js       the v(t) plot of a probed voxel
//   controls.js    the other controls, filled from the server's choices

import { connect, send, update } from './connection.js';
import { bindControls, fillControls, syncControls } from './controls.js';
import { drawProbe, onProbe } from './probe.js';
import { $, S, setStatus, viewer } from './state.js';
import { bindTF, drawTF } from './tf_editor.js';
import { bindTimeline, drawTimeline } from './timeline.js';
import { fillSelect, layoutViews, onFrame } from './views.js';

// The first message: the data sets, and the modes, menus, defaults and bounds to offer.
function onInfo(msg) {
  S.choices = msg;
  fillControls(msg);
  fillSelect(
    $('dataset'),
    msg.datasets.map((d) => ({ name: d.index, label: `${d.name} (${d.shape.join('×')})` })),
  );
  send({ type: 'open', dataset: 0 });
}

function onDataset(msg) {
  S.info = msg;
  S.state = msg.state;
  S.zoom = [0, 1];
  S.selectedPoint = Math.min(1, S.state.data_tf.points.length - 1);
  $('dataset').value = msg.index;
  syncControls();
  const size = layoutViews();
  update({ size, views: S.state.views }, 'full');
  drawTimeline();
  drawTF();
  drawProbe();
}

function onDownload(msg) {
  viewer.downloads.push(msg);
  const a = document.createElement('a');
  a.href = msg.url;
  a.download = msg.filename;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setStatus(`saved ${msg.filename}`);
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
      S.histogram = msg;
      drawTF();
      break;
    case 'probe':
      onProbe(msg);
      break;
    case 'download':
      onDownload(msg);
      break;
    case 'error':
      viewer.errors.push(msg);
      setStatus(`error: ${msg.message}`, true);
      break;
    default:
      break;
  }
}

let resizeTimer = 0;
window.addEventListener('resize', () => {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(() => {
    if (!S.state) return;
    const size = layoutViews();
    if (size[0] !== S.state.size[0]) update({ size });
    drawTimeline();
    drawTF();
    drawProbe();
  }, 150);
});

bindTimeline();
bindTF();
bindControls();
connect({ onText, onFrame });
