// Runs the unit tests (node --test test/unit/), or exits 77 (CTest SKIP_RETURN_CODE) when
// web/node_modules has not been installed (scripts/install-deps.sh --browser, or npm ci in web/).
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const web = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');
if (!fs.existsSync(path.join(web, 'node_modules', 'linkedom'))) {
  console.log('SKIP: web/node_modules missing (run npm ci in web/ or scripts/install-deps.sh --browser)');
  process.exit(77);
}
const r = spawnSync(process.execPath, ['--test', 'test/unit/'], { stdio: 'inherit', cwd: web });
process.exit(r.status ?? 1);
