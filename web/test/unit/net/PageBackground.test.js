// The colour a server-rendered frame's sky is given (issue 20 item 9): what the page shows
// behind the <xml3d>, not black.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { parseCssColor, pageBackground } from '../../../src/net/PageBackground.js';

const near = (a, b) => a.forEach((v, i) => assert.ok(Math.abs(v - b[i]) < 1e-6, `${a} != ${b}`));

// A chain of elements, innermost first, each with a computed background colour.
function chain(colours) {
  const els = colours.map((c) => ({ nodeType: 1, bg: c, parentElement: null }));
  for (let i = 0; i + 1 < els.length; i++) els[i].parentElement = els[i + 1];
  return { el: els[0], style: (e) => ({ backgroundColor: e.bg }) };
}

test('CSS colours as getComputedStyle writes them', () => {
  assert.deepEqual(parseCssColor('rgb(255, 0, 51)'), { rgb: [1, 0, 0.2], a: 1 });
  assert.deepEqual(parseCssColor('rgba(0, 0, 0, 0)'), { rgb: [0, 0, 0], a: 0 });
  near(parseCssColor('rgba(255, 255, 255, 0.25)').rgb, [1, 1, 1]);
  assert.equal(parseCssColor('rgba(255, 255, 255, 0.25)').a, 0.25);
  assert.deepEqual(parseCssColor('rgb(255 128 0 / 50%)'), { rgb: [1, 128 / 255, 0], a: 0.5 });
  for (const bad of ['', 'transparent', 'red', 'rgb(1, 2)', 'rgb(a, b, c)', undefined]) assert.equal(parseCssColor(bad), null, String(bad));
});

test('a transparent <xml3d> gets the page colour behind it, not black', () => {
  // The element and its parent transparent, the body dark blue.
  const a = chain(['rgba(0, 0, 0, 0)', 'transparent', 'rgb(0, 0, 51)', 'rgba(0, 0, 0, 0)']);
  near(pageBackground(a.el, a.style), [0, 0, 0.2]);
  // Nothing coloured anywhere: the browser's white canvas.
  const b = chain(['rgba(0, 0, 0, 0)', 'rgba(0, 0, 0, 0)']);
  near(pageBackground(b.el, b.style), [1, 1, 1]);
  // An opaque element colour wins, whatever is behind it.
  const c = chain(['rgb(0, 0, 255)', 'rgb(255, 0, 0)']);
  near(pageBackground(c.el, c.style), [0, 0, 1]);
  // Half-transparent red over white is pink; over a black body, dark red.
  const d = chain(['rgba(255, 0, 0, 0.5)', 'rgba(0, 0, 0, 0)']);
  near(pageBackground(d.el, d.style), [1, 0.5, 0.5]);
  const e = chain(['rgba(255, 0, 0, 0.5)', 'rgb(0, 0, 0)']);
  near(pageBackground(e.el, e.style), [0.5, 0, 0]);
  // A style that throws (an element without a view) counts as transparent.
  const f = chain(['rgba(0, 0, 0, 0)', 'rgb(0, 255, 0)']);
  near(pageBackground(f.el, (el) => { if (el === f.el) throw new Error('no view'); return { backgroundColor: el.bg }; }), [0, 1, 0]);
});
