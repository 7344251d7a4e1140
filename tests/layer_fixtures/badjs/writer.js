// Mutates the store it imports (under another name).
import { store as shop } from './store.js';

export function bump() {
  shop.n += 1;
}
