// The box's axes over a view's picture (with the header's "box" on): three edges of the
// volume's box, one along x, y and z, with ticks at 1-2-5 values in the data's spacing units
// and each axis' name off its edge's middle beyond the tick labels. The server picks the edges
// and projects the ticks with the view's camera (chronocl/viewer/box_axes.py, the frame
// header's `axes`: with a clip plane, of the part it keeps); here they are drawn as SVG in CSS
// pixels, each label set off from its tick on the edge's `out` side (away from the box, or into
// it along the picture's border, where the server found no room outside), and a label that
// would overlap one drawn before it (the shared corner's zeros, a foreshortened edge's ticks)
// or reach past the picture left out.

const NS = 'http://www.w3.org/2000/svg';
// As render/layout.py's LAYOUT (tick_px, tick_label_gap_px, axis_name_gap_px): a tick mark's length, a
// label's gap from the edge, the name's beyond them.
const TICK_PX = 5;
const LABEL_PX = 8;
const NAME_GAP_PX = 8;

function make(parent, tag, attrs, text) {
  const el = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (text !== undefined) el.textContent = text;
  parent.appendChild(el);
  return el;
}

// A label's anchoring for a set-off in direction [ox, oy]: it grows away from its tick.
function anchored(ox, oy) {
  return {
    'text-anchor': ox > 0.5 ? 'start' : ox < -0.5 ? 'end' : 'middle',
    'dominant-baseline': oy > 0.5 ? 'hanging' : oy < -0.5 ? 'auto' : 'central',
  };
}

const overlap = (a, b) =>
  a.x < b.x + b.width && b.x < a.x + a.width && a.y < b.y + b.height && b.y < a.y + a.height;

// `svg` (over the picture, as large) with `edges` drawn on it, or emptied (null: box off).
export function showAxes(svg, edges) {
  svg.replaceChildren();
  if (!edges || !edges.length) return;
  const W = svg.clientWidth || svg.parentNode.clientWidth;
  const H = svg.clientHeight || svg.parentNode.clientHeight;
  svg.setAttribute('viewBox', `0 0 ${W} ${H}`);
  const kept = [];
  const label = (g, x, y, text, attrs) => {
    const t = make(g, 'text', { x, y, ...attrs }, text);
    const b = t.getBBox();
    const cut = b.x < 0 || b.y < 0 || b.x + b.width > W || b.y + b.height > H;
    if (cut || kept.some((k) => overlap(b, k))) {
      t.remove();
      return null;
    }
    kept.push(b);
    return b;
  };
  for (const e of edges) {
    const g = make(svg, 'g', { class: `box-axis axis-${e.axis}`, 'data-axis': e.axis });
    const [ox, oy] = e.out;
    make(g, 'line', { class: 'edge', x1: e.from[0] * W, y1: e.from[1] * H, x2: e.to[0] * W, y2: e.to[1] * H });
    let reach = 0;
    for (const t of e.ticks) {
      const x = t.x * W;
      const y = t.y * H;
      const b = label(g, x + ox * LABEL_PX, y + oy * LABEL_PX, t.label, { class: 'tick-label', ...anchored(ox, oy) });
      if (!b) continue;
      make(g, 'line', { class: 'tick', x1: x, y1: y, x2: x + ox * TICK_PX, y2: y + oy * TICK_PX });
      reach = Math.max(reach, Math.abs(ox) * b.width + Math.abs(oy) * b.height);
    }
    // Beyond the labels, kept on the picture (an edge along the picture's border).
    const off = LABEL_PX + reach + NAME_GAP_PX;
    const nx = Math.min(Math.max(e.name.x * W + ox * off, NAME_GAP_PX), W - NAME_GAP_PX);
    const ny = Math.min(Math.max(e.name.y * H + oy * off, NAME_GAP_PX), H - NAME_GAP_PX);
    label(g, nx, ny, e.name.label, {
      class: 'axis-name', 'text-anchor': 'middle', 'dominant-baseline': 'central',
    });
  }
}
