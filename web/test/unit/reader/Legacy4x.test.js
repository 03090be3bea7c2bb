// XML3D 4.x markup that real pages still use (the xml3d-tutorial lessons, the Xflow image
// processing examples of xml3d-examples, pages converted half-way to 5.x): <shader> referenced
// by shader="#id" or style="shader: url(#id)", <light shader="#ls"> with a <lightshader>,
// <view position orientation fieldOfView>, <xml3d activeView>, visible="false", transparency,
// texture wrapS/wrapT, and 5.x details of the same pages (mesh type case, unknown material
// models). Each test fails without its fix; the conformance pages are
// web/test/pages/v4-*.html (docs/web-client.md, "XML3D 4.x markup").
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { MarkupReader } from '../../../src/reader/MarkupReader.js';
import * as M from '../../../src/math/Mat4.js';

const read = (body) => {
  const doc = page(body);
  const scene = new MarkupReader().read(doc.querySelector('xml3d'));
  return { doc, scene };
};
const near = (a, b, eps = 1e-5) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);
const nearAll = (a, b, eps = 1e-5) => { assert.equal(a.length, b.length); a.forEach((v, i) => near(v, b[i], eps)); };
const TRI = '<float3 name="position">-1 -1 0 1 -1 0 0 1 0</float3>';
const messages = (list) => list.map((e) => e.message);

test('4.x <shader script> referenced by shader="#id" on a group and style="shader: url(#id)" on a mesh', () => {
  const { scene } = read(`<xml3d>
    <shader id="orange" script="urn:xml3d:shader:matte"><float3 name="diffuseColor">1 0.5 0</float3></shader>
    <shader id="blue" script="urn:xml3d:shader:phong"><float3 name="diffuseColor">0 0 1</float3></shader>
    <group shader="#orange"><mesh id="a">${TRI}</mesh></group>
    <mesh id="b" style="shader: url(#blue)">${TRI}</mesh>
    <group shader="#orange"><mesh id="c" material="#blue">${TRI}</mesh></group></xml3d>`);
  const [a, b, c] = [...scene.meshes.values()].map((m) => scene.materials.get(m.material));
  assert.equal(a.model, 'matte');
  assert.deepEqual(a.diffuseColor, [1, 0.5, 0], 'not the default red');
  assert.equal(b.model, 'phong');
  assert.deepEqual(b.diffuseColor, [0, 0, 1]);
  assert.deepEqual(c.diffuseColor, [0, 0, 1], 'the mesh\'s own reference wins over the group\'s');
  assert.deepEqual(scene.errors, []);
  assert.deepEqual(scene.warnings, []);
});

test('phongvs is phong; a model the page registers itself gives one warning, not an error, and draws as phong', () => {
  const { scene } = read(`<xml3d>
    <shader id="vs" script="urn:xml3d:shader:phongvs"><float3 name="emissiveColor">1 1 0</float3></shader>
    <material id="eye" model="urn:xml3d:material:eyelight"><float3 name="diffuseColor">0 1 0</float3></material>
    <group shader="#vs"><mesh>${TRI}</mesh></group>
    <mesh material="#eye">${TRI}</mesh><mesh material="#eye">${TRI}</mesh></xml3d>`);
  const [vs, eye] = [...scene.meshes.values()].map((m) => scene.materials.get(m.material));
  assert.equal(vs.model, 'phong');
  assert.deepEqual(vs.emissiveColor, [1, 1, 0]);
  assert.equal(eye.model, 'phong');
  assert.deepEqual(eye.diffuseColor, [0, 1, 0], 'its parameters are kept');
  assert.deepEqual(scene.errors, [], 'valid markup: no red status line');
  assert.equal(scene.warnings.length, 1, messages(scene.warnings).join('\n'));
  assert.match(scene.warnings[0].message, /^<material id="eye"> model="urn:xml3d:material:eyelight" is not supported/);
});

test('4.x transparency is 1 - opacity', () => {
  const { scene } = read(`<xml3d>
    <shader id="glass" script="urn:xml3d:shader:phong"><float name="transparency">0.25</float></shader>
    <mesh shader="#glass">${TRI}</mesh><mesh shader="#glass">${TRI}<float name="transparency">1</float></mesh></xml3d>`);
  const [a, b] = [...scene.meshes.values()].map((m) => scene.materials.get(m.material));
  near(a.opacity, 0.75);
  near(b.opacity, 0);  // a mesh-level override
});

test('4.x <view position orientation fieldOfView> places the camera', () => {
  const { scene } = read(`<xml3d><view position="10 1 2" orientation="0 1 0 1.5707963" fieldOfView="0.6"></view>
    <mesh>${TRI}</mesh></xml3d>`);
  const cam = scene.camera;
  near(cam.fovY, 0.6);
  nearAll([cam.toWorld[12], cam.toWorld[13], cam.toWorld[14]], [10, 1, 2]);
  // It looks down its own -Z, turned 90 degrees about +Y: along world -X.
  nearAll(M.transformDirection(cam.toWorld, [0, 0, -1]), [-1, 0, 0]);
  // The tutorial's <view position="0 0 100"> alone.
  const t = read(`<xml3d><view position="0 0 100"></view><mesh>${TRI}</mesh></xml3d>`).scene.camera;
  near(t.toWorld[14], 100);
  near(t.fovY, Math.PI / 4);
  // Under a transformed group, after the view's own transform; fovVertical wins over fieldOfView.
  const g = read(`<xml3d><group style="transform: translateX(5px)"><view style="transform: translateY(2px)"
    position="0 0 3" fieldOfView="0.6"><float name="fovVertical">0.9</float></view></group><mesh>${TRI}</mesh></xml3d>`).scene.camera;
  nearAll([g.toWorld[12], g.toWorld[13], g.toWorld[14]], [5, 2, 3]);
  near(g.fovY, 0.9);
});

test('4.x <xml3d activeView="#id"> chooses the view', () => {
  const { scene } = read(`<xml3d activeView="#b"><view id="a"></view><view id="b" position="0 0 7"></view>
    <mesh>${TRI}</mesh></xml3d>`);
  assert.equal(scene.camera.element.id, 'b');
  near(scene.camera.toWorld[14], 7);
  assert.deepEqual(scene.errors, []);
});

test('4.x <light shader="#ls"> takes its type and parameters from the <lightshader>, times intensity="k"', () => {
  const { scene } = read(`<xml3d>
    <lightshader id="pl" script="urn:xml3d:lightshader:point">
      <float3 name="intensity">2 4 6</float3><float3 name="attenuation">1 0 0.5</float3></lightshader>
    <lightshader id="sl" script="urn:xml3d:lightshader:spot"><float name="falloffAngle">0.3</float>
      <float name="softness">0.2</float></lightshader>
    <lightshader id="dl" script="urn:xml3d:lightshader:directional"></lightshader>
    <group style="transform: translate3d(1px, 2px, 3px)"><light id="p" shader="#pl" intensity="0.5"></light></group>
    <light id="s" style="shader: url(#sl)"></light>
    <light id="d" shader="#dl" visible="false"></light>
    <mesh>${TRI}</mesh></xml3d>`);
  const [p, s, d] = [...scene.lights.values()];
  assert.equal(p.type, 'point');
  assert.deepEqual(p.color, [1, 2, 3], 'the float3 intensity times the intensity attribute');
  assert.deepEqual(p.attenuation, [1, 0, 0.5]);
  nearAll(p.position, [1, 2, 3]);
  assert.equal(s.type, 'spot');
  near(s.cutoff, 0.3, 1e-6);
  near(s.softness, 0.2, 1e-6);
  assert.equal(d.type, 'directional');
  assert.equal(d.on, false, 'visible="false" turns it off');
  assert.equal(p.on, true);
  assert.deepEqual(scene.errors, []);
});

test('4.x visible="false" hides a mesh, and a group with everything in it', () => {
  const { scene } = read(`<xml3d>
    <group visible="false"><mesh id="a">${TRI}</mesh><group><mesh id="b">${TRI}</mesh></group></group>
    <mesh id="c" visible="FALSE">${TRI}</mesh><mesh id="d" visible="true">${TRI}</mesh><mesh id="e">${TRI}</mesh></xml3d>`);
  assert.deepEqual([...scene.meshes.values()].map((m) => [m.element.id, m.visible]),
    [['a', false], ['b', false], ['c', false], ['d', true], ['e', true]]);
});

test('4.x texture wrapS/wrapT and filterMag when wrap and filter are absent', () => {
  const { scene } = read(`<xml3d>
    <material id="m" model="urn:xml3d:material:phong">
      <texture name="diffuseTexture" wrapS="repeat" wrapT="clamp" filterMag="nearest"><img src="a.png"></texture></material>
    <material id="n" model="urn:xml3d:material:phong">
      <texture name="diffuseTexture" wrap="clamp" wrapS="repeat"><img src="a.png"></texture></material>
    <mesh material="#m">${TRI}<float2 name="texcoord">0 0 1 0 0 1</float2></mesh>
    <mesh material="#n">${TRI}<float2 name="texcoord">0 0 1 0 0 1</float2></mesh></xml3d>`);
  const [m, n] = [...scene.meshes.values()].map((x) => scene.textures.get(scene.materials.get(x.material).diffuseTexture));
  assert.deepEqual([m.wrapS, m.wrapT, m.filter], ['repeat', 'clamp', 'nearest']);
  assert.deepEqual([n.wrapS, n.wrapT], ['clamp', 'clamp'], 'the 5.x attribute wins');
});

test('mesh type is read without regard to case, as xml3d.js does', () => {
  const { scene } = read(`<xml3d><mesh type="Triangles">${TRI}</mesh>
    <mesh type="TriStrips"><float3 name="position">0 0 0 1 0 0 0 1 0 1 1 0</float3></mesh></xml3d>`);
  assert.equal(scene.meshes.size, 2);
  assert.deepEqual(scene.errors, []);
});

test('bad 4.x values are errors and fall back: view pose, fieldOfView, light intensity and shader', () => {
  const camera = (viewAttrs) => read(`<xml3d><view id="v" ${viewAttrs}></view></xml3d>`).scene;
  let scene = camera('position="1 2" orientation="0 1 0 0.5"');
  assert.deepEqual(messages(scene.errors), ['<view id="v"> position="1 2" needs 3 numbers']);
  nearAll(scene.camera.toWorld, M.axisAngle(0, 1, 0, 0.5));
  scene = camera('position="1e999 0 0" orientation="0 1 0 NaN"');
  assert.deepEqual(messages(scene.errors), ['<view id="v"> position="1e999 0 0" is not finite',
    '<view id="v"> orientation="0 1 0 NaN" needs 4 numbers']);
  nearAll(scene.camera.toWorld, M.identity());
  for (const fov of ['0', '-1', '3.2']) {
    scene = camera(`fieldOfView="${fov}"`);
    assert.equal(scene.errors.length, 1, `fieldOfView="${fov}"`);
    assert.match(scene.errors[0].message, /outside \(0, pi\)/);
    near(scene.camera.fovY, Math.PI / 4);
  }
  scene = read(`<xml3d><lightshader id="ls" script="urn:xml3d:lightshader:point"></lightshader>
    <shader id="s" script="urn:xml3d:shader:phong"></shader>
    <light id="a" shader="#ls" intensity="bright"></light><light id="b" shader="#s"></light></xml3d>`).scene;
  assert.deepEqual(messages(scene.errors), ['<light id="a"> intensity="bright" is not a number',
    '<light id="b"> shader="#s" points at <shader>, not <lightshader>']);
  for (const l of scene.lights.values()) assert.ok(l.color.every(Number.isFinite));
});
