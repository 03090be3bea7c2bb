// Runs the browser tests, or exits 77 (CTest SKIP_RETURN_CODE) when chromium is missing.
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const dir = path.dirname(fileURLToPath(import.meta.url));
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';  // as in browser.js
if (!fs.existsSync(path.resolve(dir, '../../node_modules/playwright-core'))) {
  console.log('SKIP: web/node_modules missing (run npm ci in web/ or scripts/install-deps.sh --browser)');
  process.exit(77);
}
if (!fs.existsSync(CHROMIUM)) {
  console.log(`SKIP: ${CHROMIUM} not found (install it with scripts/install-deps.sh --browser)`);
  process.exit(77);
}
const files = fs.readdirSync(dir).filter((f) => f.endsWith('.test.js')).map((f) => path.join(dir, f));
const r = spawnSync(process.execPath, ['--test', '--test-concurrency=1', ...files.concat(process.argv.slice(2).length ? [] : [])],
  { stdio: 'inherit', cwd: path.resolve(dir, '../..') });
process.exit(r.status ?? 1);
