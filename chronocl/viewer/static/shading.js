// Lighting: a toggle and the ambient / diffuse / specular strengths of the gradient shading
// (chronocl/render/shading.py), sent as the update's `shading` field. The controls are built
// here into the side panel's <details id="lighting">; their bounds come from the server's
// choices (ranges.shading). Sliders preview while dragged and ask for a full frame on release.

import { update } from './connection.js';
import { $ } from './state.js';

// The page's state (state.js: pageState), made by app.js and given to bindShading.
let S;

const STRENGTHS = ['ambient', 'diffuse', 'specular'];

export function bindShading(page) {
  ({ S } = page);
  const box = $('lighting');
  box.innerHTML = `
    <summary>Lighting</summary>
    <div class="grid">
      <label title="Light the volume from the camera by its opacity gradient (Blinn–Phong): shape and depth for single-colour regions; slower to draw">
        <input type="checkbox" id="shading-on"> shade</label>
      <span class="hint">headlight, opacity gradient</span>
      ${STRENGTHS.map((k) => `
      <label for="shading-${k}">${k}</label>
      <input id="shading-${k}" type="range" step="0.05" min="0" max="2">`).join('')}
    </div>`;
  const send = (quality) => {
    const shading = { ...S.state.shading, enabled: $('shading-on').checked };
    for (const k of STRENGTHS) shading[k] = Number($(`shading-${k}`).value);
    update({ shading }, quality);
    syncEnabled();
  };
  $('shading-on').addEventListener('change', () => send('full'));
  for (const k of STRENGTHS) {
    $(`shading-${k}`).addEventListener('input', () => send('preview'));
    $(`shading-${k}`).addEventListener('change', () => send('full'));
  }
}

// The controls as the state has them (a data set opened, the view restored).
export function syncShading() {
  const sh = S.state && S.state.shading;
  if (!sh) return;
  const ranges = (S.choices && S.choices.ranges.shading) || {};
  $('shading-on').checked = sh.enabled;
  for (const k of STRENGTHS) {
    const el = $(`shading-${k}`);
    if (ranges[k]) [el.min, el.max] = ranges[k];
    el.value = sh[k];
  }
  syncEnabled();
}

function syncEnabled() {
  for (const k of STRENGTHS) $(`shading-${k}`).disabled = !$('shading-on').checked;
}
