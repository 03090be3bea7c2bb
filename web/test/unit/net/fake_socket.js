// A WebSocket stand-in for the unit tests of the sync channel and the displays: records the
// decoded messages the page sends, lets the test answer with server records.
import { encodeServer, decodeClient } from '../../../src/net/Protocol.js';

export class FakeSocket {
  static last = null;
  constructor(url) { this.url = url; this.readyState = 1; this.bufferedAmount = 0; this.sent = []; FakeSocket.last = this; queueMicrotask(() => this.onopen()); }
  send(bytes) { this.sent.push(decodeClient(bytes)); }
  close() { this.readyState = 3; }
  reply(records) { this.onmessage({ data: encodeServer(records).buffer }); }
}
