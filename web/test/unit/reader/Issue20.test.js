// Markup that real XML3D 5 pages use and the reader once got wrong (issue 20). Each test
// fails without its fix; the matching conformance page is in web/test/pages/.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { MarkupReader } from '../../../src/reader/MarkupReader.js';

const read = (body, opts = {}) => {
  const doc = page(body);
  const scene = new MarkupReader(opts).read(doc.querySelector('xml3d'));
  return { doc, scene };
};
const only = (map) => { assert.equal(map.size, 1); return [...map.values()][0]; };
const near = (a, b, eps = 1e-5) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);

const TRI = '<float3 name="position">-1 -1 0 1 -1 0 0 1 0</float3>';

test('useVertexColor true takes effect (not read as an RGB triple because it ends in "Color")', () => {
  const { scene } = read(`<xml3d><defs><material id="m" model="urn:xml3d:material:matte">
      <bool name="useVertexColor">true</bool></material></defs>
    <mesh material="#m">${TRI}<float3 name="color">1 0 0 0 1 0 0 0 1</float3></mesh>
    <mesh material="#m">${TRI}<bool name="useVertexColor">false</bool></mesh></xml3d>`);
  const [a, b] = [...scene.meshes.values()];
  assert.equal(scene.materials.get(a.material).useVertexColor, true);
  assert.ok(a.colors, 'the colour buffer is kept');
  assert.equal(scene.materials.get(b.material).useVertexColor, false, 'a mesh-level override turns it off');
  assert.deepEqual(scene.errors, []);
});
