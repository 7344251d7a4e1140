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
  // cell deleted) it lets the worker go, and a view shown again resumes it. Sent before the
  // viewer starts, so that it comes before the viewer's own messages.
  model.send({ view: 'shown' });
  const { viewer, stop } = app.start(
    { root, shell, keys: shell, fragment: false, global: false },
    connection.modelTransport(model),
  );
  host.viewer = viewer; // for scripted use (the tests), as window.viewer is the page's
  host.widgetManager = model.widget_manager; // (the tests close the model through it)
  // anywidget calls this when the view is removed (its output cleared, its cell deleted).
  return () => {
    model.off('change:height', height);
    stop();
    try {
      model.send({ view: 'gone' });
    } catch {
      // the model closed (its comm gone): the kernel freed the worker already
    }
  };
}

export default { render };
