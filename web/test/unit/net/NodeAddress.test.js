import { test } from 'node:test';
import assert from 'node:assert/strict';
import { nodeAddress } from '../../../src/net/RemoteBackend.js';

test('a bare host:port follows the page: TLS on an https page, none on http', () => {
  assert.deepEqual(nodeAddress('node.example:8443', 'https:'), { host: 'node.example:8443', secure: true });
  assert.deepEqual(nodeAddress('127.0.0.1:8080', 'http:'), { host: '127.0.0.1:8080', secure: false });
  assert.deepEqual(nodeAddress(' [::1]:8080 ', 'file:'), { host: '[::1]:8080', secure: false });
});

test('a scheme in the server attribute decides, whatever the page', () => {
  for (const s of ['wss://node.example:8443', 'https://node.example:8443/', 'WSS://node.example:8443/ws'])
    assert.deepEqual(nodeAddress(s, 'http:'), { host: 'node.example:8443', secure: true }, s);
  for (const s of ['ws://10.0.0.2:8080', 'http://10.0.0.2:8080/x?y#z'])
    assert.deepEqual(nodeAddress(s, 'https:'), { host: '10.0.0.2:8080', secure: false }, s);
});
