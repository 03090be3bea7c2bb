import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { launch, open, pixel } from './browser.js';

let env;
before(async () => { env = await launch(); });
after(async () => { await env.close(); });

test('the WebGL fallback draws a red box in the centre, transparent elsewhere', async () => {
  const page = await open(env, '/test/browser/pages/redbox.html');
  const centre = await pixel(page, 100, 75);
  assert.deepEqual(centre, [255, 0, 0, 255], page.logs.join('\n'));
  const corner = await pixel(page, 5, 5);
  assert.equal(corner[3], 0);
  await page.close();
});
