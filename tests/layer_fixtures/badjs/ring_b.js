// Import cycle, half two.
import { a } from './ring_a.js';

export const b = () => (a ? 1 : 0);
