// chronocl viewer page: sends state changes over a WebSocket, shows the frames the server
// renders. No build step, no dependencies. The server renders the newest state only, so
// the page may send freely; it still coalesces input to one message per animation frame.
'use strict';

(() => {
  const $ = (id) => document.getElementById(id);
  const MODES = ['alpha', 'first_hit', 'additive', 'max', 'min'];
  const ENHANCE_DEFAULTS = { none: [1, 0, 1], edge: [0.2, 6, 1], silhouette: [0.15, 1, 1] };
  const MAX_PANEL = 768;

  const params = new URLSearchParams(location.search);
  const token = params.get('token') || '';
  if (token) history.replaceState(null, '', location.pathname); // the cookie keeps us in

  // What the page shows; `viewer` is also read by the tests.
  const S = {
    info: null, // the data set: shape, stats
    state: null, // protocol state (camera, views, window, data_tf, time_tf, ...)
    histogram: null,
    zoom: [0, 1], // data TF editor's visible range of u
    selectedPoint: 1,
    selectedView: 0,
    legend: [],
    playing: false,
  };
  const viewer = (window.viewer = {
    frames: 0, full: 0, sent: 0, last: null, errors: [], probe: null, downloads: [], S,
  });

  let ws = null;
  let nextId = 1;
  let lastSentId = 0;
  const sentAt = new Map();

  // ------------------------------------------------------------------ connection
  function connect() {
    const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
    const q = token ? `?token=${encodeURIComponent(token)}` : '';
    ws = new WebSocket(`${proto}//${location.host}/ws${q}`);
    ws.binaryType = 'arraybuffer';
    ws.onmessage = (e) => (typeof e.data === 'string' ? onText(JSON.parse(e.data)) : onFrame(e.data));
    ws.onclose = () => setStatus('disconnected: reload the page (is the server still running?)', true);
  }

  function send(msg) {
    if (!ws || ws.readyState !== WebSocket.OPEN) return 0;
    msg.id = nextId++;
    sentAt.set(msg.id, performance.now());
    if (sentAt.size > 200) sentAt.delete(sentAt.keys().next().value);
    ws.send(JSON.stringify(msg));
    return msg.id;
  }

  // Updates are merged and sent once per animation frame.
  let pending = null;
  let pendingQuality = 'full';
  function update(fields, quality = 'full') {
    pending = Object.assign(pending || {}, fields);
    pendingQuality = quality;
    Object.assign(S.state, fields);
    requestAnimationFrame(flush);
  }
  function flush() {
    if (!pending) return;
    const msg = Object.assign({ type: 'update', quality: pendingQuality }, pending);
    pending = null;
    lastSentId = send(msg);
    viewer.sent = lastSentId;
  }
  let settleTimer = 0;
  function settleLater(ms = 250) {
    clearTimeout(settleTimer);
    settleTimer = setTimeout(() => update({}, 'full'), ms);
  }

  function onText(msg) {
    switch (msg.type) {
      case 'info': {
        const sel = $('dataset');
        sel.innerHTML = '';
        for (const d of msg.datasets) {
          const o = document.createElement('option');
          o.value = d.index;
          o.textContent = `${d.name} (${d.shape.join('×')})`;
          sel.appendChild(o);
        }
        send({ type: 'open', dataset: 0 });
        break;
      }
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
      case 'download': {
        viewer.downloads.push(msg);
        const a = document.createElement('a');
        a.href = msg.url;
        a.download = msg.filename;
        document.body.appendChild(a);
        a.click();
        a.remove();
        setStatus(`saved ${msg.filename}`);
        break;
      }
      case 'error':
        viewer.errors.push(msg);
        setStatus(`error: ${msg.message}`, true);
        break;
      default:
        break;
    }
  }

  // ------------------------------------------------------------------ data set
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

  function syncControls() {
    const st = S.state;
    $('nviews').value = st.views.length;
    $('projection').value = st.camera.projection;
    $('background').value = st.background;
    $('outline').checked = st.outline;
    $('time-color').value = st.time_tf.color;
    $('time-alpha').value = st.time_tf.alpha;
    $('t-center').value = st.time_tf.center;
    $('t-width').value = st.time_tf.width;
    $('t-floor').value = st.time_tf.floor;
    $('positions').value = st.time_tf.positions;
    $('enhance').value = st.enhance.kind;
    $('k0').value = st.enhance.k0;
    $('k1').value = st.enhance.k1;
    $('k2').value = st.enhance.k2;
    $('threshold').value = st.threshold;
    $('clip-on').checked = !!st.clip;
    $('stride').value = st.window.stride;
    syncTimeControls();
    syncPointColor();
  }
  function syncTimeControls() {
    const hat = S.state.time_tf.alpha !== 'constant';
    for (const id of ['t-center', 't-width', 't-floor']) $(id).disabled = !hat;
  }

  // ------------------------------------------------------------------ views
  const panels = [];
  function layoutViews() {
    const n = S.state.views.length;
    const box = $('views');
    while (panels.length > n) panels.pop().el.remove();
    while (panels.length < n) panels.push(makePanel(panels.length));
    panels.forEach((p, i) => {
      p.mode.value = S.state.views[i].mode;
      p.order.textContent = S.state.views[i].order || 'forward';
      p.el.classList.toggle('selected', i === S.selectedView && n > 1);
    });
    // The grid (columns x rows) that gives the largest square panels.
    const gap = 6;
    let cols = 1;
    let side = 0;
    for (let c = n; c >= 1; c--) {
      const r = Math.ceil(n / c);
      const w = (box.clientWidth - 12 - gap * (c - 1)) / c;
      const h = (box.clientHeight - 12 - gap * (r - 1)) / r;
      const s = Math.floor(Math.min(w, h, MAX_PANEL) / 8) * 8;
      if (s > side * 1.1) [cols, side] = [c, s]; // more rows only for clearly larger panels
    }
    side = Math.max(64, side);
    box.style.gridTemplateColumns = `repeat(${cols}, ${side}px)`;
    for (const p of panels) {
      p.el.style.width = `${side}px`;
      p.el.style.height = `${side}px`;
    }
    return [side, side];
  }

  function makePanel(i) {
    const el = document.createElement('div');
    el.className = 'view';
    el.dataset.i = i;
    el.innerHTML =
      '<img alt="view" draggable="false"><div class="view-head">' +
      `<select class="mode" title="Integration mode">${MODES.map((m) => `<option>${m}</option>`).join('')}</select>` +
      '<button class="order" title="Integration order (which steps are in front)">forward</button>' +
      '</div><div class="view-label"></div><div class="probe-mark"></div>';
    $('views').appendChild(el);
    const p = {
      el,
      img: el.querySelector('img'),
      mode: el.querySelector('.mode'),
      order: el.querySelector('.order'),
      label: el.querySelector('.view-label'),
      mark: el.querySelector('.probe-mark'),
    };
    p.mode.addEventListener('change', () => {
      const views = S.state.views.map((v) => ({ ...v }));
      views[i].mode = p.mode.value;
      update({ views });
    });
    p.order.addEventListener('click', () => {
      const views = S.state.views.map((v) => ({ ...v }));
      views[i].order = views[i].order === 'backward' ? 'forward' : 'backward';
      p.order.textContent = views[i].order;
      update({ views });
    });
    bindOrbit(p, i);
    return p;
  }

  function bindOrbit(p, i) {
    let start = null;
    p.img.addEventListener('pointerdown', (e) => {
      if (!S.state) return;
      p.img.setPointerCapture(e.pointerId);
      start = { x: e.clientX, y: e.clientY, cam: { ...S.state.camera }, moved: false };
    });
    p.img.addEventListener('pointermove', (e) => {
      if (!start) return;
      const dx = e.clientX - start.x;
      const dy = e.clientY - start.y;
      if (!start.moved && Math.hypot(dx, dy) < 3) return;
      start.moved = true;
      const cam = { ...S.state.camera };
      cam.azimuth = start.cam.azimuth - dx * 0.5;
      cam.elevation = Math.max(-89, Math.min(89, start.cam.elevation + dy * 0.5));
      update({ camera: cam }, 'preview');
    });
    const end = (e) => {
      if (!start) return;
      const wasDrag = start.moved;
      start = null;
      if (wasDrag) update({ camera: { ...S.state.camera } }, 'full');
      else if (e.type === 'pointerup') probeAt(p, i, e);
    };
    p.img.addEventListener('pointerup', end);
    p.img.addEventListener('pointercancel', end);
    p.img.addEventListener(
      'wheel',
      (e) => {
        e.preventDefault();
        const cam = { ...S.state.camera };
        cam.zoom = Math.max(0.2, Math.min(20, cam.zoom * Math.exp(-e.deltaY * 0.0015)));
        update({ camera: cam }, 'preview');
        settleLater();
      },
      { passive: false },
    );
  }

  function probeAt(p, i, e) {
    const r = p.img.getBoundingClientRect();
    const x = Math.min(1, Math.max(0, (e.clientX - r.left) / r.width));
    const y = Math.min(1, Math.max(0, (e.clientY - r.top) / r.height));
    S.selectedView = i;
    panels.forEach((q, j) => q.el.classList.toggle('selected', j === i && panels.length > 1));
    for (const q of panels) q.mark.style.display = 'none';
    p.mark.style.left = `${x * 100}%`;
    p.mark.style.top = `${y * 100}%`;
    p.mark.style.display = 'block';
    send({ type: 'probe', view: i, x, y });
  }

  // ------------------------------------------------------------------ frames
  function fnv(bytes, h) {
    for (let k = 0; k < bytes.length; k++) {
      h ^= bytes[k];
      h = Math.imul(h, 16777619) >>> 0;
    }
    return h;
  }

  function onFrame(buf) {
    const n = new DataView(buf).getUint32(0);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
    let at = 4 + n;
    let digest = 2166136261;
    header.views.forEach((v, i) => {
      const bytes = new Uint8Array(buf, at, v.bytes);
      at += v.bytes;
      digest = fnv(bytes, digest);
      const p = panels[i];
      if (!p) return;
      const url = URL.createObjectURL(new Blob([bytes], { type: 'image/jpeg' }));
      const old = p.img.dataset.url;
      p.img.src = url;
      p.img.dataset.url = url;
      if (old) URL.revokeObjectURL(old);
      p.label.textContent = v.label;
    });
    S.legend = header.legend || [];
    const now = performance.now();
    const t0 = sentAt.get(header.id);
    viewer.frames += 1;
    if (header.quality === 'full') viewer.full += 1;
    viewer.last = {
      id: header.id, seq: header.seq, quality: header.quality, digest, views: header.views.length,
      timings: header.timings, roundTripMs: t0 === undefined ? null : now - t0,
    };
    document.body.dataset.frames = viewer.frames;
    showTimings(header);
    drawTimeline();
  }

  function showTimings(h) {
    const t = h.timings;
    const v = h.views[0];
    const kb = h.views.reduce((s, x) => s + x.bytes, 0) / 1024;
    const rt = viewer.last.roundTripMs;
    const parts = [
      `integrate ${t.integrate_ms.toFixed(1)} ms${t.incremental ? ' (incremental)' : ''}`,
      `upload ${t.upload_ms.toFixed(1)} ms`,
      `render ${t.render_ms.toFixed(1)} ms`,
      `encode ${t.encode_ms.toFixed(1)} ms`,
      `${h.views.length}× ${v.width}×${v.height} ${h.format} ${kb.toFixed(0)} KB (${h.quality})`,
    ];
    if (rt !== null) parts.push(`round trip ${rt.toFixed(0)} ms`);
    setStatus(parts.join(' · '));
  }

  let statusTimer = 0;
  function setStatus(text, bad = false) {
    const el = $('status');
    if (!bad && el.classList.contains('error') && Date.now() < statusTimer) return;
    el.textContent = text;
    el.classList.toggle('error', bad);
    if (bad) statusTimer = Date.now() + 4000;
  }

  // ------------------------------------------------------------------ timeline
  const tl = { drag: null };
  function canvasSize(c) {
    const r = c.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(r.width * dpr));
    const h = Math.max(1, Math.round(r.height * dpr));
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    const ctx = c.getContext('2d');
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    return [ctx, r.width, r.height];
  }

  function drawTimeline() {
    if (!S.info) return;
    const [ctx, w, h] = canvasSize($('timeline'));
    const T = S.info.shape.t;
    const cell = w / T;
    const { t0, t1, stride } = S.state.window;
    ctx.clearRect(0, 0, w, h);
    const top = 14;
    const bottom = h - 14;
    const ph = bottom - top;
    const range = S.info.vmax - S.info.vmin || 1;
    const meanMax = Math.max(...S.info.step_mean.map((v) => v - S.info.vmin), 1e-12);
    // The window.
    ctx.fillStyle = 'rgba(240,160,48,0.16)';
    ctx.fillRect(t0 * cell, 0, (t1 - t0) * cell, h);
    // Sparklines: mean (filled, own scale) and max (line, over the value range).
    ctx.beginPath();
    ctx.moveTo(0, bottom);
    S.info.step_mean.forEach((v, s) => ctx.lineTo((s + 0.5) * cell, bottom - ((v - S.info.vmin) / meanMax) * ph));
    ctx.lineTo(w, bottom);
    ctx.closePath();
    ctx.fillStyle = 'rgba(120,160,210,0.35)';
    ctx.fill();
    ctx.beginPath();
    S.info.step_max.forEach((v, s) => {
      const y = bottom - ((v - S.info.vmin) / range) * ph;
      if (s === 0) ctx.moveTo((s + 0.5) * cell, y);
      else ctx.lineTo((s + 0.5) * cell, y);
    });
    ctx.strokeStyle = 'rgba(230,230,230,0.8)';
    ctx.lineWidth = 1.2;
    ctx.stroke();
    // Selected steps, coloured by their time colour.
    const colours = new Map(S.legend.map((l) => [l.step, l]));
    for (let s = t0; s < t1; s += stride) {
      const l = colours.get(s);
      ctx.fillStyle = l ? `rgb(${l.rgb.map((c) => Math.round(c * 255)).join(',')})` : '#f0a030';
      ctx.fillRect(s * cell + cell * 0.15, bottom + 2, Math.max(2, cell * 0.7), 5);
    }
    // Brush edges.
    ctx.strokeStyle = '#f0a030';
    ctx.lineWidth = 2;
    ctx.strokeRect(t0 * cell + 1, 1, (t1 - t0) * cell - 2, h - 2);
    // Axis labels.
    ctx.fillStyle = '#8b949e';
    ctx.font = '10px system-ui, sans-serif';
    ctx.textBaseline = 'bottom';
    ctx.fillText('0', 3, h - 1);
    ctx.textAlign = 'right';
    ctx.fillText(String(T - 1), w - 3, h - 1);
    ctx.textAlign = 'left';
    ctx.textBaseline = 'top';
    ctx.fillText('max ─  mean ▆', 3, 2);
    $('window-text').textContent = `steps ${t0}:${t1}${stride > 1 ? ':' + stride : ''} (${Math.ceil((t1 - t0) / stride)} of ${T})`;
  }

  function setWindow(t0, t1, stride, quality = 'full') {
    const T = S.info.shape.t;
    t0 = Math.max(0, Math.min(T - 1, t0));
    t1 = Math.max(t0 + 1, Math.min(T, t1));
    const w = S.state.window;
    if (w.t0 === t0 && w.t1 === t1 && w.stride === stride) return false;
    update({ window: { t0, t1, stride } }, quality);
    drawTimeline();
    return true;
  }

  function slide(k) {
    const { t0, t1, stride } = S.state.window;
    const T = S.info.shape.t;
    let shift = k * stride;
    shift = Math.max(-t0, Math.min(shift, T - t1));
    if (!shift) return false;
    return setWindow(t0 + shift, t1 + shift, stride);
  }

  function bindTimeline() {
    const c = $('timeline');
    const stepAt = (e) => {
      const r = c.getBoundingClientRect();
      return ((e.clientX - r.left) / r.width) * S.info.shape.t;
    };
    c.addEventListener('pointerdown', (e) => {
      if (!S.info) return;
      c.setPointerCapture(e.pointerId);
      const x = stepAt(e);
      const { t0, t1 } = S.state.window;
      const edge = (0.25 * S.info.shape.t * 8) / c.getBoundingClientRect().width; // 8 px in steps
      let kind = 'new';
      if (Math.abs(x - t0) < Math.max(edge, 0.25)) kind = 'left';
      else if (Math.abs(x - t1) < Math.max(edge, 0.25)) kind = 'right';
      else if (x > t0 && x < t1) kind = 'move';
      tl.drag = { kind, x0: x, t0, t1, anchor: Math.floor(x) };
    });
    c.addEventListener('pointermove', (e) => {
      if (!tl.drag) return;
      const x = stepAt(e);
      const d = tl.drag;
      const stride = S.state.window.stride;
      if (d.kind === 'move') {
        const T = S.info.shape.t;
        let shift = Math.round(x - d.x0);
        shift = Math.max(-d.t0, Math.min(shift, T - d.t1));
        setWindow(d.t0 + shift, d.t1 + shift, stride, 'preview');
      } else if (d.kind === 'left') {
        setWindow(Math.min(Math.round(x), d.t1 - 1), d.t1, stride, 'preview');
      } else if (d.kind === 'right') {
        setWindow(d.t0, Math.max(Math.round(x), d.t0 + 1), stride, 'preview');
      } else {
        const a = d.anchor;
        const b = Math.floor(x);
        setWindow(Math.min(a, b), Math.max(a, b) + 1, stride, 'preview');
      }
    });
    const end = () => {
      if (!tl.drag) return;
      tl.drag = null;
      update({}, 'full');
    };
    c.addEventListener('pointerup', end);
    c.addEventListener('pointercancel', end);
    $('stride').addEventListener('change', () => {
      const s = Math.max(1, Math.min(S.info.shape.t, parseInt($('stride').value, 10) || 1));
      $('stride').value = s;
      setWindow(S.state.window.t0, S.state.window.t1, s);
    });
    $('play').addEventListener('click', () => setPlaying(!S.playing));
    document.addEventListener('keydown', (e) => {
      if (!S.info || e.target.closest('input, select, textarea')) return;
      if (e.key === 'ArrowRight') slide(1);
      else if (e.key === 'ArrowLeft') slide(-1);
      else if (e.key === ' ') setPlaying(!S.playing);
      else return;
      e.preventDefault();
    });
  }

  let playTimer = 0;
  function setPlaying(on) {
    S.playing = on;
    $('play').textContent = on ? '❚❚' : '▶';
    clearInterval(playTimer);
    if (!on) return;
    playTimer = setInterval(() => {
      // Wait for the frame of the last request before sliding again.
      if (viewer.last && viewer.last.id < lastSentId) return;
      if (!slide(1)) {
        const { t0, t1, stride } = S.state.window;
        setWindow(0, t1 - t0, stride);
      }
    }, 90);
  }

  // ------------------------------------------------------------------ data TF editor
  const tf = { drag: null };
  const pad = { l: 6, r: 6, t: 8, b: 18 };
  function tfGeom() {
    const [ctx, w, h] = canvasSize($('tf'));
    const [lo, hi] = S.zoom;
    const X = (u) => pad.l + ((u - lo) / (hi - lo)) * (w - pad.l - pad.r);
    const U = (x) => lo + ((x - pad.l) / (w - pad.l - pad.r)) * (hi - lo);
    const Y = (a) => h - pad.b - a * (h - pad.t - pad.b);
    const A = (y) => (h - pad.b - y) / (h - pad.t - pad.b);
    return { ctx, w, h, X, U, Y, A };
  }
  const rgbCss = (p, a = 1) => `rgba(${Math.round(p[1] * 255)},${Math.round(p[2] * 255)},${Math.round(p[3] * 255)},${a})`;
  const dataValue = (u) => S.info.vmin + u * (S.info.vmax - S.info.vmin);
  const fmt = (v) => (Math.abs(v) >= 1e4 || (Math.abs(v) < 1e-3 && v !== 0) ? v.toExponential(2) : +v.toPrecision(4));

  function drawTF() {
    if (!S.state) return;
    const { ctx, w, h, X, Y } = tfGeom();
    const pts = S.state.data_tf.points;
    ctx.clearRect(0, 0, w, h);
    const hist = S.histogram;
    if (hist && hist.range[0] === S.zoom[0] && hist.range[1] === S.zoom[1]) {
      const n = hist.counts.length;
      const top = Math.log1p(Math.max(...hist.counts, 1));
      ctx.fillStyle = 'rgba(120,160,210,0.45)';
      const bw = (w - pad.l - pad.r) / n;
      hist.counts.forEach((c, i) => {
        const bh = (Math.log1p(c) / top) * (h - pad.t - pad.b);
        ctx.fillRect(pad.l + i * bw, h - pad.b - bh, Math.max(1, bw - 0.5), bh);
      });
    }
    // Colour strip under the curve: the TF's colour with its opacity.
    const grad = ctx.createLinearGradient(X(pts[0][0]), 0, X(pts[pts.length - 1][0]), 0);
    const span = pts[pts.length - 1][0] - pts[0][0] || 1;
    for (const p of pts) grad.addColorStop((p[0] - pts[0][0]) / span, rgbCss(p, 0.25 + 0.75 * p[4]));
    ctx.fillStyle = grad;
    ctx.fillRect(pad.l, h - pad.b + 2, w - pad.l - pad.r, 5);
    // Opacity curve and points.
    ctx.beginPath();
    ctx.moveTo(X(S.zoom[0]), Y(pts[0][4]));
    for (const p of pts) ctx.lineTo(X(p[0]), Y(p[4]));
    ctx.lineTo(X(S.zoom[1]), Y(pts[pts.length - 1][4]));
    ctx.strokeStyle = '#f0a030';
    ctx.lineWidth = 1.5;
    ctx.stroke();
    pts.forEach((p, i) => {
      ctx.beginPath();
      ctx.arc(X(p[0]), Y(p[4]), i === S.selectedPoint ? 6 : 4.5, 0, 2 * Math.PI);
      ctx.fillStyle = rgbCss(p);
      ctx.fill();
      ctx.lineWidth = i === S.selectedPoint ? 2.5 : 1.2;
      ctx.strokeStyle = i === S.selectedPoint ? '#f0a030' : '#222';
      ctx.stroke();
    });
    ctx.fillStyle = '#8b949e';
    ctx.font = '10px system-ui, sans-serif';
    ctx.textBaseline = 'bottom';
    if (S.info) {
      ctx.textAlign = 'left';
      ctx.fillText(String(fmt(dataValue(S.zoom[0]))), pad.l, h);
      ctx.textAlign = 'right';
      ctx.fillText(String(fmt(dataValue(S.zoom[1]))), w - pad.r, h);
      ctx.textAlign = 'left';
      $('zoom-lo').value = fmt(dataValue(S.zoom[0]));
      $('zoom-hi').value = fmt(dataValue(S.zoom[1]));
    }
  }

  function sendTF(quality) {
    update({ data_tf: { points: S.state.data_tf.points.map((p) => p.slice()) } }, quality);
    drawTF();
  }

  function syncPointColor() {
    const p = S.state.data_tf.points[S.selectedPoint];
    if (!p) return;
    const hex = (v) => Math.round(v * 255).toString(16).padStart(2, '0');
    $('point-color').value = `#${hex(p[1])}${hex(p[2])}${hex(p[3])}`;
  }

  function bindTF() {
    const c = $('tf');
    const at = (e) => {
      const r = c.getBoundingClientRect();
      return [e.clientX - r.left, e.clientY - r.top];
    };
    const clamp01 = (v) => Math.max(0, Math.min(1, v));
    c.addEventListener('pointerdown', (e) => {
      if (!S.state || e.button !== 0) return;
      const g = tfGeom();
      const [x, y] = at(e);
      const pts = S.state.data_tf.points;
      let best = -1;
      let bestD = 9;
      pts.forEach((p, i) => {
        const d = Math.hypot(g.X(p[0]) - x, g.Y(p[4]) - y);
        if (d < bestD) [best, bestD] = [i, d];
      });
      if (best < 0) {
        // A new point on the curve's colour at that value.
        const u = clamp01(g.U(x));
        if (pts.some((p) => Math.abs(p[0] - u) < 1e-4) || pts.length >= 64) return;
        let k = pts.findIndex((p) => p[0] > u);
        if (k < 0) k = pts.length;
        const a = pts[Math.max(0, k - 1)];
        const b = pts[Math.min(pts.length - 1, k)];
        const f = b[0] === a[0] ? 0 : (u - a[0]) / (b[0] - a[0]);
        const rgb = [1, 2, 3].map((j) => a[j] + f * (b[j] - a[j]));
        pts.splice(k, 0, [u, ...rgb, clamp01(g.A(y))]);
        best = k;
      }
      S.selectedPoint = best;
      syncPointColor();
      c.setPointerCapture(e.pointerId);
      tf.drag = { i: best };
      sendTF('preview');
    });
    c.addEventListener('pointermove', (e) => {
      if (!tf.drag) return;
      const g = tfGeom();
      const [x, y] = at(e);
      const pts = S.state.data_tf.points;
      const i = tf.drag.i;
      const lo = i > 0 ? pts[i - 1][0] + 1e-4 : 0;
      const hi = i < pts.length - 1 ? pts[i + 1][0] - 1e-4 : 1;
      pts[i][0] = Math.max(lo, Math.min(hi, clamp01(g.U(x))));
      pts[i][4] = clamp01(g.A(y));
      sendTF('preview');
    });
    const end = () => {
      if (!tf.drag) return;
      tf.drag = null;
      sendTF('full');
    };
    c.addEventListener('pointerup', end);
    c.addEventListener('pointercancel', end);
    const remove = () => {
      const pts = S.state.data_tf.points;
      if (pts.length <= 2) return;
      pts.splice(S.selectedPoint, 1);
      S.selectedPoint = Math.min(S.selectedPoint, pts.length - 1);
      syncPointColor();
      sendTF('full');
    };
    c.addEventListener('dblclick', remove);
    $('tf-delete').addEventListener('click', remove);
    $('point-color').addEventListener('input', () => {
      const p = S.state.data_tf.points[S.selectedPoint];
      const hex = $('point-color').value;
      [1, 2, 3].forEach((j, k) => (p[j] = parseInt(hex.slice(1 + 2 * k, 3 + 2 * k), 16) / 255));
      sendTF('full');
    });
    c.addEventListener(
      'wheel',
      (e) => {
        e.preventDefault();
        const g = tfGeom();
        const u = g.U(at(e)[0]);
        const f = Math.exp(e.deltaY * 0.002);
        const [lo, hi] = S.zoom;
        let nlo = u - (u - lo) * f;
        let nhi = u + (hi - u) * f;
        if (nhi - nlo < 1e-3) return;
        setZoom(Math.max(0, nlo), Math.min(1, nhi));
      },
      { passive: false },
    );
    $('tf-reset-zoom').addEventListener('click', () => setZoom(0, 1));
    const fromInputs = () => {
      const span = S.info.vmax - S.info.vmin || 1;
      const lo = (parseFloat($('zoom-lo').value) - S.info.vmin) / span;
      const hi = (parseFloat($('zoom-hi').value) - S.info.vmin) / span;
      if (Number.isFinite(lo) && Number.isFinite(hi) && hi - lo > 1e-4) setZoom(Math.max(0, lo), Math.min(1, hi));
      else drawTF();
    };
    $('zoom-lo').addEventListener('change', fromInputs);
    $('zoom-hi').addEventListener('change', fromInputs);
  }

  let histTimer = 0;
  function setZoom(lo, hi) {
    S.zoom = [lo, hi];
    drawTF();
    clearTimeout(histTimer);
    histTimer = setTimeout(() => send({ type: 'histogram', range: [lo, hi] }), 120);
  }

  // ------------------------------------------------------------------ probe plot
  function onProbe(msg) {
    viewer.probe = msg;
    drawProbe();
    const txt = $('probe-text');
    if (!msg.voxel) {
      txt.textContent = 'this ray meets no opaque voxel; click on a feature';
      return;
    }
    const v = msg.voxel;
    const how = msg.reached ? 'opacity passes 0.5' : `strongest sample (opacity ${msg.opacity})`;
    txt.textContent = `voxel x=${v.x} y=${v.y} z=${v.z} (${how}) · view ${msg.view + 1}`;
  }

  function drawProbe() {
    const c = $('probe');
    const [ctx, w, h] = canvasSize(c);
    ctx.clearRect(0, 0, w, h);
    const msg = viewer.probe;
    if (!S.info || !msg || !msg.values) return;
    const T = msg.values.length;
    const p = { l: 40, r: 6, t: 8, b: 16 };
    const vmin = S.info.vmin;
    const vmax = S.info.vmax > vmin ? S.info.vmax : vmin + 1;
    const X = (s) => p.l + (T > 1 ? s / (T - 1) : 0.5) * (w - p.l - p.r);
    const Y = (v) => h - p.b - ((v - vmin) / (vmax - vmin)) * (h - p.t - p.b);
    const win = msg.window;
    ctx.fillStyle = 'rgba(240,160,48,0.16)';
    ctx.fillRect(X(win[0]) - 2, p.t, X(win[win.length - 1]) - X(win[0]) + 4, h - p.t - p.b);
    ctx.strokeStyle = '#343941';
    ctx.lineWidth = 1;
    ctx.strokeRect(p.l, p.t, w - p.l - p.r, h - p.t - p.b);
    ctx.beginPath();
    msg.values.forEach((v, s) => (s === 0 ? ctx.moveTo(X(s), Y(v)) : ctx.lineTo(X(s), Y(v))));
    ctx.strokeStyle = '#7fb8ff';
    ctx.lineWidth = 1.6;
    ctx.stroke();
    ctx.fillStyle = '#f0a030';
    for (const s of win) {
      ctx.beginPath();
      ctx.arc(X(s), Y(msg.values[s]), 2.6, 0, 2 * Math.PI);
      ctx.fill();
    }
    ctx.fillStyle = '#8b949e';
    ctx.font = '10px system-ui, sans-serif';
    ctx.textAlign = 'right';
    ctx.textBaseline = 'middle';
    ctx.fillText(String(fmt(vmax)), p.l - 3, p.t + 3);
    ctx.fillText(String(fmt(vmin)), p.l - 3, h - p.b - 2);
    ctx.textBaseline = 'bottom';
    ctx.textAlign = 'left';
    ctx.fillText('t = 0', p.l, h);
    ctx.textAlign = 'right';
    ctx.fillText(String(T - 1), w - p.r, h);
    c.dataset.drawn = String(Number(c.dataset.drawn || 0) + 1);
  }

  // ------------------------------------------------------------------ other controls
  function bindControls() {
    $('dataset').addEventListener('change', () => send({ type: 'open', dataset: Number($('dataset').value) }));
    $('nviews').addEventListener('change', () => {
      const n = Number($('nviews').value);
      const views = S.state.views.slice(0, n).map((v) => ({ ...v }));
      const defaults = ['alpha', 'additive', 'max', 'first_hit'];
      while (views.length < n) {
        const used = new Set(views.map((v) => v.mode));
        views.push({ mode: defaults.find((m) => !used.has(m)) || 'alpha', order: 'forward' });
      }
      S.state.views = views;
      S.selectedView = Math.min(S.selectedView, n - 1);
      const size = layoutViews();
      update({ views, size });
    });
    $('projection').addEventListener('change', () =>
      update({ camera: { ...S.state.camera, projection: $('projection').value } }));
    $('background').addEventListener('change', () => update({ background: $('background').value }));
    $('outline').addEventListener('change', () => update({ outline: $('outline').checked }));

    const timeTF = (quality) => {
      const t = {
        color: $('time-color').value,
        alpha: $('time-alpha').value,
        center: Number($('t-center').value),
        width: Number($('t-width').value),
        floor: Number($('t-floor').value),
        positions: $('positions').value,
      };
      syncTimeControls();
      update({ time_tf: Object.assign({}, S.state.time_tf, t) }, quality);
    };
    for (const id of ['time-color', 'time-alpha', 'positions']) $(id).addEventListener('change', () => timeTF('full'));
    for (const id of ['t-center', 't-width', 't-floor']) {
      $(id).addEventListener('input', () => timeTF('preview'));
      $(id).addEventListener('change', () => timeTF('full'));
    }

    $('enhance').addEventListener('change', () => {
      const kind = $('enhance').value;
      const [k0, k1, k2] = ENHANCE_DEFAULTS[kind];
      $('k0').value = k0;
      $('k1').value = k1;
      $('k2').value = k2;
      update({ enhance: { kind, k0, k1, k2 } });
    });
    for (const id of ['k0', 'k1', 'k2']) {
      $(id).addEventListener('change', () => {
        const v = Number($(id).value);
        if (!Number.isFinite(v) || v < 0) return;
        update({ enhance: { [id]: v } });
      });
    }
    $('threshold').addEventListener('change', () => {
      const v = Number($('threshold').value);
      if (Number.isFinite(v) && v >= 0 && v <= 0.99) update({ threshold: v });
    });

    const clip = (quality) => {
      if (!$('clip-on').checked) return update({ clip: null }, quality);
      const normal = $('clip-axis').value.split(',').map(Number);
      update({ clip: { normal, offset: Number($('clip-offset').value) } }, quality);
    };
    $('clip-on').addEventListener('change', () => clip('full'));
    $('clip-axis').addEventListener('change', () => clip('full'));
    $('clip-offset').addEventListener('input', () => $('clip-on').checked && clip('preview'));
    $('clip-offset').addEventListener('change', () => $('clip-on').checked && clip('full'));

    $('save-image').addEventListener('click', () => send({ type: 'save', what: 'image' }));
    $('save-cv').addEventListener('click', () =>
      send({ type: 'save', what: 'chronovolume', view: S.selectedView }));

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
  }

  // Page coordinates of editor handles, for scripted use (the browser tests).
  viewer.tfPointAt = (i) => {
    const g = tfGeom();
    const r = $('tf').getBoundingClientRect();
    const p = S.state.data_tf.points[i];
    return { x: r.left + g.X(p[0]), y: r.top + g.Y(p[4]) };
  };
  viewer.timelineAt = (step) => {
    const r = $('timeline').getBoundingClientRect();
    return { x: r.left + ((step + 0.5) / S.info.shape.t) * r.width, y: r.top + r.height / 2 };
  };

  bindTimeline();
  bindTF();
  bindControls();
  connect();
})();
