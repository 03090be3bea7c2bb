// Runs the browser tests, or exits 77 (CTest SKIP_RETURN_CODE) when something they need is missing.
//   node test/browser/run.js                                   the tests against the mock node (CTest web_browser)
//   node test/browser/run.js --tessera BIN node-e2e.test.js    the tests against a real node (CTest web_node_e2e)
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const dir = path.dirname(fileURLToPath(import.meta.url));
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';  // as in browser.js
const args = process.argv.slice(2);
let tessera = null;
const t = args.indexOf('--tessera');
if (t >= 0) { tessera = args[t + 1]; args.splice(t, 2); }
if (!fs.existsSync(path.resolve(dir, '../../node_modules/playwright-core'))) {
  console.log('SKIP: web/node_modules missing (run npm ci in web/ or scripts/install-deps.sh --browser)');
  process.exit(77);
}
if (!fs.existsSync(CHROMIUM)) {
  console.log(`SKIP: ${CHROMIUM} not found (install it with scripts/install-deps.sh --browser)`);
  process.exit(77);
}
const REAL_NODE = (f) => f.startsWith('node-');  // these need a tessera binary
const files = args.length ? args : fs.readdirSync(dir).filter((f) => f.endsWith('.test.js') && !REAL_NODE(f));
for (const f of files) {
  if (!fs.existsSync(path.join(dir, f))) { console.error(`no test file ${f} in ${dir}`); process.exit(2); }
  if (REAL_NODE(f) && !tessera) { console.error(`${f} needs --tessera PATH (the built tessera binary)`); process.exit(2); }
}
if (tessera && !fs.existsSync(tessera)) {
  console.log(`SKIP: tessera binary ${tessera} not found (build it: ninja -C build tessera)`);
  process.exit(77);
}
const r = spawnSync(process.execPath, ['--test', '--test-concurrency=1', ...files.map((f) => path.join(dir, f))],
  { stdio: 'inherit', cwd: path.resolve(dir, '../..'), env: { ...process.env, ...(tessera ? { TESSERA_BIN: path.resolve(tessera) } : {}) } });
process.exit(r.status ?? 1);
