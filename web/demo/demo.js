// Shared code of the demo pages: places the view from data-eye / data-target / data-fov on
// the <view>, and switches between local WebGL and server rendering.
//   ?server=host:port   render on that Tessera node (default: local WebGL)
//   ?display=jpeg|s3tc|mjpeg|h264|auto&video-kbps=K&ao-samples=N&max-depth=D&refine-samples=R&frame-budget=MS&sync-rate=HZ
//                      override the page's <xml3d> attributes
import { lookAt, toAxisAngle } from '../src/math/Mat4.js';

const xml3d = document.querySelector('xml3d');
const view = xml3d.querySelector('view');
const num = (s) => s.split(/[\s,]+/).map(Number);
if (view && view.dataset.eye) {
  const m = lookAt(num(view.dataset.eye), num(view.dataset.target), [0, 1, 0]);
  const t = document.getElementById(view.getAttribute('transform').slice(1));
  t.setAttribute('translation', `${m[12]} ${m[13]} ${m[14]}`);
  t.setAttribute('rotation', toAxisAngle(m).join(' '));
}

const params = new URLSearchParams(location.search);
const defaultServer = params.get('server') || `${location.hostname}:${location.port || 80}`;
for (const a of ['display', 'video-kbps', 'ao-samples', 'max-depth', 'refine-samples', 'frame-budget', 'references', 'sync-rate']) if (params.has(a)) xml3d.setAttribute(a, params.get(a));
if (params.get('server')) xml3d.setAttribute('server', params.get('server'));
// The client starts only now, so that it finds the page as the query made it, as it finds a page
// written with these attributes: imported first, it would set up WebGL and load the whole glTF,
// then build everything again for each attribute above (server, display) that changed.
await import('../src/xml3d.js');

// The switch: toggling the server attribute makes xml3d.js rebuild the backend.
const bar = document.getElementById('controls');
if (bar) {
  const box = document.createElement('label');
  box.innerHTML = `<input type="checkbox" id="remote"> render on Tessera node <input id="host" size="18">
    AO rays <select id="ao">${[0, 1, 2, 4, 8, 16].map((n) => `<option>${n}</option>`).join('')}</select>
    <span id="info"></span>`;
  bar.appendChild(box);
  const remote = box.querySelector('#remote'), host = box.querySelector('#host'), info = box.querySelector('#info');
  remote.checked = xml3d.hasAttribute('server');
  host.value = xml3d.getAttribute('server') || defaultServer;
  const apply = () => {
    if (remote.checked) xml3d.setAttribute('server', host.value); else xml3d.removeAttribute('server');
  };
  remote.addEventListener('change', apply);
  // AO rays per hit on the node (the ao-samples attribute; sent as a settings record).
  const ao = box.querySelector('#ao');
  ao.value = xml3d.getAttribute('ao-samples') || '0';
  ao.addEventListener('change', () => xml3d.setAttribute('ao-samples', ao.value));
  host.addEventListener('change', () => remote.checked && apply());
  let frames = 0, last = performance.now();
  xml3d.addEventListener('framedrawn', () => {
    frames++;
    const now = performance.now();
    if (now - last > 1000) {
      info.textContent = ` ${(frames * 1000 / (now - last)).toFixed(1)} frames/s, ${xml3d.hasAttribute('server') ? 'server' : 'WebGL'}`;
      frames = 0; last = now;
    }
  });
}
