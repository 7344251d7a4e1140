// Import cycle, half one (a multi-line import, as formatters write long ones).
import {
  b,
} from './ring_b.js';

export const a = () => b() + 1;
