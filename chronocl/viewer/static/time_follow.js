// Time colours that follow the data TF, as `TimeTF.for_data` does in the API and the command
// line (docs/semantics.md, "Colour maps and time colours"): colour c = rgb_d(u) * rgb_t(p), so a
// colour map times the rgb time colours multiplies into dark mud. Choosing a colour-map preset
// in the TF editor therefore sets the time colours to `lightness` (time as lightness under the
// map's hue), or back to `rgb` for a map without hue (grey), unless the time colours were
// chosen in this page (the time colour menu) or are another preset than those two.

import { shown, update } from './connection.js';
import { $ } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindTimeFollow.
let S;

const HUE_TOLERANCE = 0.02; // chronocl/core/colormaps.py: channels further apart make a hue
const chosen = { byUser: false };

export const hasHue = (points) =>
  points.some((p) => Math.max(p[1], p[2], p[3]) - Math.min(p[1], p[2], p[3]) > HUE_TOLERANCE);

// The time colours for data TF `points`, where they follow it. Call it just before the data
// TF's own update: its change travels in the same message and is one undo step with it (its
// 'preview' quality is replaced by that update's).
export function followDataTF(points) {
  const now = shown('time_tf').color;
  if (chosen.byUser || !['rgb', 'lightness'].includes(now)) return;
  const color = hasHue(points) ? 'lightness' : 'rgb';
  if (color === now) return;
  update({ time_tf: { ...shown('time_tf'), color } }, 'preview');
  $('time-color').value = color;
}

// A time colour chosen in the menu is kept from then on.
export function bindTimeFollow(page) {
  ({ S } = page);
  $('time-color').addEventListener('change', () => {
    chosen.byUser = true;
  });
}
