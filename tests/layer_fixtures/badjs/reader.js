// Only reads, but what it reads is shared mutable state: it should be passed in instead.
import { count, fixed, store, tick } from './store.js';

export const seen = () => {
  tick();
  return store.n + count + (fixed.n >= 1 ? 1 : 0);
};
