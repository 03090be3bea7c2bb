// An XML3D 4.x page written as XHTML (application/xhtml+xml, XML3D elements in their namespace),
// loaded through the classic entry src/xml3d-classic.js (docs/web-client.md, "XHTML pages").
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { launch, open, pixel } from './browser.js';

let env;
before(async () => { env = await launch(); });
after(async () => { await env.close(); });

test('an XHTML 4.x page: the classic entry loads, shaders, a 4.x view and inline styles of namespaced elements apply', async () => {
  const page = await open(env, '/test/browser/pages/v4-xhtml.xhtml');
  const ns = await page.evaluate(() => document.getElementById('x').namespaceURI);
  assert.equal(ns, 'http://www.xml3d.org/2009/xml3d', 'the page is parsed as XML');
  const at = (x, y) => pixel(page, x, y);
  assert.deepEqual(await at(47, 60), [0, 255, 0, 255], 'green left: style="transform: …" on a namespaced group');
  assert.deepEqual(await at(120, 60), [0, 0, 255, 255], 'blue middle: the white style="display: none" mesh is not drawn');
  assert.deepEqual(await at(139, 79), [0, 0, 255, 255], 'blue near its corner');
  assert.deepEqual(await at(192, 60), [255, 255, 0, 255], 'yellow right: phongvs, transform="#right"');
  assert.equal((await at(84, 60))[3], 0, 'nothing between the squares');
  assert.deepEqual(page.logs.filter((l) => /^(error|pageerror|warning: XML3D)/.test(l)), [], page.logs.join('\n'));
  const errors = await page.evaluate(() => document.getElementById('x').tessera.scene.errors.map((e) => e.message));
  assert.deepEqual(errors, []);
  await page.close();
});
