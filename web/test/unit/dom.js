// A light DOM for the markup reader's unit tests (linkedom).
import { parseHTML } from 'linkedom';

export function page(body, url = 'http://localhost/page.html') {
  const { document } = parseHTML(`<!DOCTYPE html><html><head></head><body>${body}</body></html>`);
  Object.defineProperty(document, 'baseURI', { value: url, configurable: true });
  return document;
}
