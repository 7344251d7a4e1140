// The viewer page (index.html): the viewer started in the document, on the server's WebSocket.

import { start } from './app.js';
import { socketTransport } from './connection.js';

start({}, socketTransport());
