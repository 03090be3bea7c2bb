// The classic entry src/xml3d-classic.js, for pages that swap xml3d.js's <script src> for ours
// one to one. xml3d.js is a classic script, so pages use window.XML3D from DOMContentLoaded
// handlers (jQuery's ready) and window load handlers (`new XML3D.StandardCamera(view, …)`);
// a module loaded with import() delays neither event, and on the examples' pages those
// handlers threw "XML3D is not defined". While the parser runs the entry, it must write a
// module <script> after itself (the parser's module scripts run before DOMContentLoaded);
// later in an HTML document it appends one (that holds the load event back); XML documents
// run no module script elements, so they keep import().
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { parseHTML } from 'linkedom';

const SRC = fs.readFileSync(path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../../../src/xml3d-classic.js'), 'utf8');
const LIB = 'http://example.test/lib/xml3d.js';

// Runs the entry as the browser would run <script src="http://example.test/lib/xml3d-classic.js">
// in a document of the given content type and ready state. `imported`: what it passed to
// import(); `written`: what it passed to document.write.
function runEntry(contentType, readyState) {
  const { document, Event } = parseHTML('<!DOCTYPE html><html><head><script src="http://example.test/lib/xml3d-classic.js"></script></head><body><xml3d></xml3d></body></html>');
  Object.defineProperty(document, 'contentType', { value: contentType });
  Object.defineProperty(document, 'readyState', { value: readyState });
  Object.defineProperty(document, 'currentScript', { value: document.querySelector('script') });
  const written = [];
  document.write = (html) => { if (contentType !== 'text/html') throw new Error('no write in XML'); written.push(html); };
  const imported = [];
  // import() is syntax, not a function a test can replace: the call is rewritten to a stand-in.
  const body = SRC.replace(/\bimport\(/g, '__import(');
  const fn = new Function('document', 'location', '__import', 'console', body);
  fn(document, { href: 'http://example.test/page.html' }, (u) => { imported.push(u); return Promise.resolve(); },
    { error: (m) => assert.fail(`unexpected console.error: ${m}`) });
  const modules = () => [...document.querySelectorAll('script')].filter((s) => s.getAttribute('type') === 'module');
  const dcl = () => document.dispatchEvent(new Event('DOMContentLoaded'));
  return { document, imported, written, modules, dcl };
}

test('classic entry while an HTML page is parsed: writes a module script after itself, which runs before DOMContentLoaded', () => {
  const { document, imported, written, modules, dcl } = runEntry('text/html', 'loading');
  assert.deepEqual(imported, [], 'no import(), which delays neither DOMContentLoaded nor load');
  assert.equal(written.length, 1);
  const { document: frag } = parseHTML(`<html><head>${written[0]}</head></html>`);
  const s = frag.querySelector('script');
  assert.equal(s.getAttribute('type'), 'module');
  assert.equal(s.getAttribute('src'), LIB);
  assert.equal(modules().length, 0, 'nothing appended as well');
  // Once the parser has made the written element, DOMContentLoaded appends nothing more.
  document.head.insertAdjacentHTML('beforeend', written[0]);
  dcl();
  assert.equal(modules().length, 1);
});

test('classic entry whose write the browser ignored: a module script is appended by DOMContentLoaded', () => {
  const { modules, dcl } = runEntry('text/html', 'loading');
  dcl();
  assert.equal(modules().length, 1);
  assert.equal(modules()[0].getAttribute('src'), LIB);
});

test('classic entry in an HTML page already parsed: a module script element, which holds the load event back', () => {
  const { imported, written, modules } = runEntry('text/html', 'interactive');
  assert.deepEqual(written, [], 'no document.write once parsing is over (it would replace the page)');
  assert.deepEqual(imported, []);
  assert.equal(modules().length, 1);
  assert.equal(modules()[0].getAttribute('src'), LIB);
});

test('classic entry in an XHTML page: import(), since XML documents run no module script elements', () => {
  const { imported, written, modules } = runEntry('application/xhtml+xml', 'loading');
  assert.deepEqual(imported, [LIB]);
  assert.deepEqual(written, []);
  assert.equal(modules().length, 0);
});
