// The notebook widget's front end (anywidget): the browser viewer's own modules
// (chronocl/viewer/static), started in the cell output on the widget's comm.
//
// anywidget imports this module from a blob URL, where the viewer modules' relative imports
// (`from './state.js'`) would not resolve. So the kernel ships their sources in BUNDLE
// (chronocl/notebook/bundle.py), in an order where each module comes after the modules it
// imports, and each is linked here through a blob URL of its own, its specifiers rewritten to
// those URLs. Every view of a widget loads its own instances of the modules: each has its own
// state, and several widgets on one page do not meet. The viewer's markup (index.html's body)
// and style sheet live in a shadow root, so neither the page's ids nor its styles meet the
// notebook's.

const BUNDLE = /* BUNDLE */ null;

const IMPORT = /(\bfrom\s*)'\.\/([\w.-]+\.js)'/g;

// The viewer's modules as blob URLs, by file name (the ones to revoke once imported).
function link() {
  const urls = {};
  for (const name of BUNDLE.order) {
    const source = BUNDLE.modules[name].replace(IMPORT, (all, from, dep) => {
      if (!(dep in urls)) throw new Error(`chronocl widget: ${name} imports ${dep}, not linked before it`);
      return `${from}'${urls[dep]}'`;
    });
    urls[name] = URL.createObjectURL(new Blob([source], { type: 'text/javascript' }));
  }
  return urls;
}

async function render({ model, el }) {
  const urls = link();
  let app;
  let connection;
  try {
    [app, connection] = await Promise.all([import(urls['app.js']), import(urls['connection.js'])]);
  } finally {
    for (const url of Object.values(urls)) URL.revokeObjectURL(url);
  }
  const host = document.createElement('div');
  host.className = 'chronocl-widget';
  // JupyterLab's shortcuts (a, b, x, z act on cells) stay out of the viewer's keys and fields.
  host.setAttribute('data-lm-suppress-shortcuts', 'true');
  el.appendChild(host);
  const root = host.attachShadow({ mode: 'open' });
  root.innerHTML = `<style>${BUNDLE.css}\n${BUNDLE.widget_css}</style><div class="chronocl widget" tabindex="-1">${BUNDLE.markup}</div>`;
  const shell = root.querySelector('.chronocl');
  const height = () => {
    shell.style.height = `${model.get('height')}px`;
  };
  height();
  model.on('change:height', height);
  // Keys typed in the viewer are its own: the notebook does not see them.
  shell.addEventListener('keydown', (e) => e.stopPropagation());
  // The kernel counts the views shown: with none left for a while (the output cleared, the
  // cell deleted) it lets the worker go, and a view shown again resumes it. A page reloaded,
  // closed or crashed never calls the cleanup below, so the view also proves it is alive: a
  // heartbeat every `_heartbeat_s` while it exists, visible or not (a hidden page's beats say
  // so: the kernel waits longer for its throttled timers), and a best-effort 'gone' on
  // pagehide, after which it says nothing (chronocl/notebook/views.py). A page being unloaded
  // turns hidden after pagehide; that is not said: the beats say hidden, on a timer, only
  // where the page lives on hidden. "shown" is sent before the viewer starts, so that it
  // comes before the viewer's own messages.
  const id = `${Date.now().toString(36)}-${Math.random().toString(36).slice(2)}`;
  const say = (what) => {
    try {
      model.send({ view: what, id, hidden: document.visibilityState === 'hidden' });
    } catch {
      // the model closed (its comm gone): the kernel freed the worker already
    }
  };
  let beat = null;
  const beating = (on) => {
    clearInterval(beat);
    const every = Number(model.get('_heartbeat_s')) || 5; // (the kernel's HEARTBEAT_S)
    beat = on ? setInterval(() => say('alive'), 1000 * every) : null;
  };
  const visible = () => {
    if (beat !== null && document.visibilityState === 'visible') say('alive'); // (the short wait)
  };
  const pagehide = () => {
    beating(false);
    say('gone');
  };
  const pageshow = (e) => {
    if (!e.persisted) return; // (back from the back-forward cache: shown again)
    say('shown');
    beating(true);
  };
  const quiet = () => {
    document.removeEventListener('visibilitychange', visible);
    window.removeEventListener('pagehide', pagehide);
    window.removeEventListener('pageshow', pageshow);
    beating(false);
  };
  say('shown');
  beating(true);
  document.addEventListener('visibilitychange', visible);
  window.addEventListener('pagehide', pagehide);
  window.addEventListener('pageshow', pageshow);
  let started;
  try {
    started = app.start(
      { root, shell, keys: shell, fragment: false, global: false },
      connection.modelTransport(model),
    );
  } catch (err) {
    quiet(); // a view that failed to start shows nothing: it must not beat for ever
    say('gone');
    throw err;
  }
  const { viewer, stop } = started;
  host.viewer = viewer; // for scripted use (the tests), as window.viewer is the page's
  host.widgetManager = model.widget_manager; // (the tests close the model through it)
  // anywidget calls this when the view is removed (its output cleared, its cell deleted).
  return () => {
    model.off('change:height', height);
    quiet();
    stop();
    say('gone');
  };
}

export default { render };
