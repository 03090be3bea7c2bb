import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { accessToken, takeFragmentToken, withToken, redact } from '../../../src/net/AccessToken.js';
import { SyncChannel } from '../../../src/net/SyncChannel.js';
import { RemoteBackend } from '../../../src/net/RemoteBackend.js';

// A window stand-in: its location and what history.replaceState made of the address.
function fakeWindow(href) {
  const url = new URL(href);
  const win = {
    location: { pathname: url.pathname, search: url.search, hash: url.hash },
    history: {
      state: null,
      replaced: [],
      replaceState(state, title, to) { this.replaced.push(to); win.location.hash = new URL(to, url).hash; },
    },
  };
  return win;
}

const xml3d = (attrs = '') => page(`<xml3d ${attrs}></xml3d>`).querySelector('xml3d');

test('the token comes from the token attribute, else from #tessera-token= in the page URL', () => {
  const win = fakeWindow('https://app.example/page.html?x=1#tessera-token=tsr1.123.YQ.mac');
  assert.equal(accessToken(xml3d('token="from-attribute-token"'), win), 'from-attribute-token');
  assert.equal(win.history.replaced.length, 0, 'the fragment is not touched while the attribute gives the token');
  assert.equal(accessToken(xml3d(), win), 'tsr1.123.YQ.mac');
  assert.equal(accessToken(xml3d('token="  "'), fakeWindow('https://app.example/')), '');
});

test('the fragment token leaves the address bar at once and is kept for the page', () => {
  const win = fakeWindow('https://app.example/page.html?x=1#view=top&tessera-token=secret-token-0123456789');
  assert.equal(takeFragmentToken(win), 'secret-token-0123456789');
  assert.deepEqual(win.history.replaced, ['/page.html?x=1#view=top'], 'other fragment parameters stay');
  assert.equal(win.location.hash, '#view=top');
  assert.equal(takeFragmentToken(win), 'secret-token-0123456789', 'a later handler still finds it');
  const only = fakeWindow('https://app.example/p#tessera-token=abc');
  takeFragmentToken(only);
  assert.deepEqual(only.history.replaced, ['/p']);
  const none = fakeWindow('https://app.example/p#section-2');
  assert.equal(takeFragmentToken(none), '');
  assert.equal(none.history.replaced.length, 0, 'a fragment without a token is left alone');
});

test('the token goes into the query of the WebSocket and MJPEG URLs and never onto the page', () => {
  assert.equal(withToken('ws://h:8080/ws?session=abc', 'tsr1.1.YQ.m-_'), 'ws://h:8080/ws?session=abc&access_token=tsr1.1.YQ.m-_');
  assert.equal(withToken('http://h/mjpeg/abc', 'a b'), 'http://h/mjpeg/abc?access_token=a%20b');
  assert.equal(withToken('ws://h/ws?session=abc', ''), 'ws://h/ws?session=abc');
  assert.equal(redact('ws://h/ws?session=abc&access_token=tsr1.1.YQ.mac'), 'ws://h/ws?session=abc&access_token=…');
  assert.equal(redact('ws://h/ws?access_token=x&session=abc'), 'ws://h/ws?access_token=…&session=abc');
});

// A WebSocket stand-in that the node refuses with a close code and reason after the upgrade.
class RefusedSocket {
  static made = [];
  constructor(url) {
    this.url = url; this.readyState = 0; this.bufferedAmount = 0;
    RefusedSocket.made.push(this);
    setTimeout(() => { this.readyState = 1; this.onopen(); setTimeout(() => { this.readyState = 3; this.onclose({ code: 4401, reason: 'access token expired' }); }, 1); }, 1);
  }
  send() {}
  close() {}
}

test('a refused token stops the channel with the node\'s reason, and it does not reconnect', async () => {
  const saved = globalThis.WebSocket;
  globalThis.WebSocket = RefusedSocket;
  RefusedSocket.made = [];
  const states = [];
  const ch = new SyncChannel({ url: 'ws://h/ws?session=abc&access_token=tok', rate: 100,
    handshake: { renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, maxNodes: 0, width: 8, height: 8 },
    onState: (s, d) => states.push([s, d]) });
  try {
    ch.connect();
    for (let i = 0; i < 100 && !states.some(([s]) => s === 'failed'); i++) await new Promise((r) => setTimeout(r, 5));
    await new Promise((r) => setTimeout(r, 700));  // longer than the first reconnect's back-off
    assert.deepEqual(states.at(-1), ['failed', 'access token expired']);
    assert.equal(RefusedSocket.made.length, 1);
    assert.equal(RefusedSocket.made[0].url, 'ws://h/ws?session=abc&access_token=tok');
  } finally {
    ch.close();
    globalThis.WebSocket = saved;
  }
});

test('the failed session is one console error naming the reason, and the status line shows no token', () => {
  const errors = [], statuses = [];
  const saved = console.error;
  console.error = (m) => errors.push(m);
  const doc = page('<div></div>');
  let downloads = 0;  // a failed session opens the deferred glTF downloads: no reference answers are coming
  const self = { host: 'node.example:8080', url: 'ws://node.example:8080/ws?access_token=secret-token-value', frameView: {},
    handler: { container: doc.querySelector('div'), setStatus: (k, t) => statuses.push(t) }, openDownloads: () => downloads++ };
  try {
    RemoteBackend.prototype.state.call(self, 'connecting', '');
    RemoteBackend.prototype.state.call(self, 'failed', 'access token expired');
  } finally {
    console.error = saved;
  }
  assert.deepEqual(errors, ['Tessera: the node node.example:8080 refused the session: access token expired']);
  assert.equal(downloads, 1);
  assert.ok(statuses.every((t) => !t.includes('secret-token-value')), statuses.join('\n'));
  assert.ok(statuses[0].includes('access_token=…'));
});
