// Starts a real Tessera node (`tessera serve`) for browser tests and the web figures:
// web/ as web root, ../shared/scenes at /scenes/, an ephemeral port on 127.0.0.1.
import { spawn, execFileSync } from 'node:child_process';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

export const WEB = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');
export const SCENES = path.resolve(WEB, '../../shared/scenes');

// Resolves {host, port, base, info, log, close()} once the node prints its listening line.
// webRoot: another copy of web/ to serve (web-figures compares two clients that way).
export function startNode(bin, { args = [], threads = 0, webRoot = WEB } = {}) {
  const argv = ['serve', '--host', '127.0.0.1', '--port', '0', '--web-root', webRoot, '--scenes-root', SCENES, ...args];
  if (threads) argv.push('--threads', String(threads));
  const proc = spawn(bin, argv, { stdio: ['ignore', 'pipe', 'pipe'] });
  const node = { proc, log: [] };
  let err = '';
  proc.stderr.on('data', (d) => {
    err += d;
    const lines = err.split('\n');
    err = lines.pop();
    for (const l of lines) node.log.push(l);
  });
  node.close = () => new Promise((resolve) => {
    if (proc.exitCode !== null || proc.signalCode !== null) { resolve(); return; }
    proc.once('exit', () => resolve());
    proc.kill('SIGTERM');
  });
  return new Promise((resolve, reject) => {
    let out = '';
    const fail = (why) => reject(new Error(`tessera serve: ${why}\n${node.log.join('\n')}${err}`));
    proc.once('error', (e) => fail(e.message));
    proc.once('exit', (code, sig) => fail(`exited (${code ?? sig}) before listening`));
    proc.stdout.on('data', (d) => {
      out += d;
      const nl = out.indexOf('\n');
      if (nl < 0 || node.info) return;
      try { node.info = JSON.parse(out.slice(0, nl)); } catch (e) { fail(`unexpected first line: ${out.slice(0, nl)}`); return; }
      const u = new URL(node.info.listening);
      Object.assign(node, { host: u.hostname, port: Number(u.port), base: `${u.protocol}//${u.hostname}:${u.port}` });
      proc.removeAllListeners('exit');
      resolve(node);
    });
  });
}

// The node's own render of a glTF scene from frame k of a camera loop, as PNG bytes (a Buffer).
export function renderReference(bin, { scene, loop, frame = 0, width, height, out, ao = 0, depth = 4, threads = 2 }) {
  execFileSync(bin, ['render', '--scene', scene, '--camera-loop', loop, '--frame', String(frame), '--size', String(width), String(height),
    '--ao', String(ao), '--depth', String(depth), '--threads', String(threads), '--out', out], { stdio: ['ignore', 'pipe', 'pipe'] });
  return out;
}
