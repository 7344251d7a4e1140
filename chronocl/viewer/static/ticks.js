// Axis ticks for the timeline: at nice step numbers (1, 2 or 5 times a power of ten, as
// chronocl/core/ticks.py), at nice times where every step has a numeric time (with the store's
// unit), or at round clock or calendar times where every step has a date (a midnight written
// as its date, other ticks as their clock); as many as fit
// without two labels closer than GAP px. Pure functions of the data set's info and a text
// measure, so the timeline (timeline.js) only draws what they return.

const GAP = 10; // least room between two labels, CSS px
const EDGE = 2; // labels stay this far inside the axis' ends

// 1-2-5 steps from about `lo` up, each a float of its own (0.1, 0.2, 0.5, 1, 2, ...).
function* niceSteps(lo, integer) {
  let e = Math.floor(Math.log10(Math.max(lo, 1e-12)));
  for (let k = 0; k < 40; k++, e++) {
    for (const m of [1, 2, 5]) {
      const step = +(m * 10 ** e).toPrecision(12);
      if (!integer || step >= 1) yield step;
    }
  }
}

const MINUTE = 60e3;
const HOUR = 60 * MINUTE;
const DAY = 24 * HOUR;
// Clock and calendar steps (ms), from a second to a year (months and years are 30 and 365
// days: their ticks fall on the first of a month or year only by chance, so labels say dates).
const TIME_STEPS = [
  1e3, 2e3, 5e3, 10e3, 15e3, 30e3,
  MINUTE, 2 * MINUTE, 5 * MINUTE, 10 * MINUTE, 15 * MINUTE, 30 * MINUTE,
  HOUR, 2 * HOUR, 3 * HOUR, 6 * HOUR, 12 * HOUR,
  DAY, 2 * DAY, 7 * DAY, 14 * DAY, 30 * DAY, 91 * DAY, 182 * DAY, 365 * DAY,
];

const ISO = /^(\d{4}-\d{2}-\d{2})[T ](\d{2}:\d{2}(?::\d{2}(?:\.\d{1,3})?)?)\d*(Z|[+-]\d{2}:?\d{2})?$/;

// ms since the epoch of an ISO date and time ('2024-01-01T06:00:00.000000000'; no zone: UTC,
// as the server writes it), NaN otherwise.
function isoTime(text) {
  const m = ISO.exec(String(text).trim());
  if (!m) return NaN;
  return Date.parse(`${m[1]}T${m[2]}${m[3] || 'Z'}`);
}

const pad2 = (v) => String(v).padStart(2, '0');

function clockText(ms, step) {
  const d = new Date(ms);
  const date = `${d.getUTCFullYear()}-${pad2(d.getUTCMonth() + 1)}-${pad2(d.getUTCDate())}`;
  const clock = `${pad2(d.getUTCHours())}:${pad2(d.getUTCMinutes())}`;
  const secs = step < MINUTE ? `:${pad2(d.getUTCSeconds())}` : '';
  return { date, clock: step >= DAY ? '' : clock + secs };
}

// What the axis is over: per step its value (numbers increasing), and how a value is written.
// Numeric times (with the unit), dates, or the step numbers (labelled with the store's labels).
export function axisOf(info) {
  const T = info.shape.t;
  const steps = Array.from({ length: T }, (_, s) => s);
  const labels = info.time_labels;
  const increasing = (v) => v.every((x, k) => Number.isFinite(x) && (k === 0 || x > v[k - 1]));
  if (labels && info.times && info.times.length === T) {
    const numbers = info.times.map((t) => (String(t).trim() === '' ? NaN : Number(t)));
    if (increasing(numbers)) {
      const unit = info.time_unit ? ` ${info.time_unit}` : '';
      return { kind: 'number', values: numbers, integer: false, text: (v, step) => numberText(v, step) + unit };
    }
    const dates = info.times.map(isoTime);
    if (T > 1 && increasing(dates)) return { kind: 'date', values: dates };
  }
  return {
    kind: 'step', values: steps, integer: true,
    text: (v) => (labels && labels[v] !== undefined ? String(labels[v]) : String(v)),
  };
}

function numberText(v, step) {
  const decimals = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
  const text = v.toFixed(decimals);
  return /^-?[0.]+$/.test(text) ? '0' : text;
}

// The multiples of `step` within [lo, hi].
function multiples(lo, hi, step) {
  const out = [];
  const last = Math.floor(hi / step + 1e-9);
  for (let j = Math.ceil(lo / step - 1e-9); j <= last && out.length < 10000; j++) out.push(j * step);
  return out;
}

// Ticks of `axis` over an axis `w` px wide whose step s sits at xOfStep(s); `measure(text)`
// its width in px. Each tick {text, x, left, right}: x where its value falls (between the
// centres of the steps around it), left..right its label's extent, clamped inside the axis.
// The smallest nice step whose labels keep GAP px apart wins; with none, the first value alone.
export function axisTicks(axis, w, measure, xOfStep) {
  const v = axis.values;
  const n = v.length;
  const lo = v[0];
  const hi = v[n - 1];
  const at = (t) => {
    if (n === 1) return xOfStep(0);
    let k = 1;
    while (k < n - 1 && v[k] < t) k++;
    const f = Math.max(0, Math.min(1, (t - v[k - 1]) / (v[k] - v[k - 1])));
    return xOfStep(k - 1) + f * (xOfStep(k) - xOfStep(k - 1));
  };
  const place = (ticks) => {
    for (const t of ticks) {
      const tw = measure(t.text);
      const left = Math.max(EDGE, Math.min(w - EDGE - tw, t.x - tw / 2));
      Object.assign(t, { left, right: left + tw });
    }
    return ticks.every((t, k) => k === 0 || t.left >= ticks[k - 1].right + GAP);
  };
  const most = Math.max(1, Math.floor(w / (GAP + 6)));
  const candidates = [];
  if (axis.kind === 'date') {
    for (const step of TIME_STEPS) {
      // Midnight is written as its date, any other tick as its clock; where no tick falls on
      // a midnight, the first says its date too.
      const parts = multiples(lo, hi, step).map((t) => ({ t, ...clockText(t, step) }));
      const midnight = (q) => !q.clock || /^00:00(:00)?$/.test(q.clock);
      const dated = parts.some(midnight);
      const ticks = parts.map((q, k) => ({
        text: midnight(q) ? q.date : !dated && k === 0 ? `${q.date} ${q.clock}` : q.clock,
        x: at(q.t),
        value: q.t,
      }));
      candidates.push(ticks);
    }
  } else {
    const span = hi - lo;
    const first = span > 0 ? span / most : 1;
    for (const step of niceSteps(first / 10, axis.integer)) {
      const ticks = multiples(lo, hi, step).map((t) => ({ text: axis.text(t, step), x: at(t), value: t }));
      candidates.push(ticks);
      if (ticks.length <= 1) break;
    }
  }
  for (const ticks of candidates) {
    if (!ticks.length || ticks.length > most) continue;
    if (place(ticks)) return ticks;
  }
  // Nothing fits (an axis narrower than two labels): the first value alone.
  const first = { text: axis.kind === 'date' ? clockText(lo, DAY).date : axis.text(lo, 1), x: at(lo), value: lo };
  place([first]);
  return [first];
}
