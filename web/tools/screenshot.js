// Screenshots a page once its <xml3d> has loaded: node tools/screenshot.js /demo/basic.html out.png
import { launch, open } from '../test/browser/browser.js';

const [url, out = 'screenshot.png'] = process.argv.slice(2);
const env = await launch();
try {
  const page = await open(env, url, { waitLoad: !process.env.NO_WAIT });
  if (process.env.NO_WAIT) await page.waitForTimeout(3000);
  await page.setViewportSize({ width: 1000, height: 700 });
  await page.waitForTimeout(500);
  await page.screenshot({ path: out });
  console.log(page.logs.join('\n'));
} finally { await env.close(); }
