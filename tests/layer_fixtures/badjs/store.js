// Exports that others import: `store` and `list` are mutated by their importers, `count` is a
// live `let`; `fixed` is only read, and is fine.
export const store = { n: 0 };
export const list = [];
export let count = 0;
export const fixed = { n: 1 };

export function tick() {
  count += 1;
}
