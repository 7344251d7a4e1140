// Mutates the list it imports through a method.
import { fixed, list } from './store.js';

export function more() {
  if (fixed.n === 1) list.push(fixed.n);
}
