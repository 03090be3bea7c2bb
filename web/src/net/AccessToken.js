// The access token a page gives the client for a node that asks for one (docs/web-client.md,
// "Access tokens"; docs/protocol.md, "Access tokens"): the `token` attribute of <xml3d>, else
// `#tessera-token=...` in the page URL's fragment. A fragment never leaves the browser (it is
// in no request line, Referer or server log); the client also takes it out of the address bar
// (history.replaceState), so that it is not bookmarked or copied with the page's address, and
// keeps it for the page's life (a later handler, e.g. after the server attribute changed,
// finds it here).
const FRAGMENT_KEY = 'tessera-token';
export const QUERY_KEY = 'access_token';

const fromFragment = new WeakMap();  // window -> the token its fragment held

// The token in the window's URL fragment ('' when none); removes it from the address bar.
export function takeFragmentToken(win) {
  if (!win || !win.location) return '';
  if (fromFragment.has(win)) return fromFragment.get(win);
  const params = new URLSearchParams(win.location.hash.replace(/^#/, ''));
  const token = params.get(FRAGMENT_KEY) || '';
  if (!token) return '';
  params.delete(FRAGMENT_KEY);
  const rest = params.toString();
  try {
    win.history.replaceState(win.history.state, '', `${win.location.pathname}${win.location.search}${rest ? `#${rest}` : ''}`);
  } catch { /* a page without history (a sandboxed frame): the token stays in its fragment */ }
  fromFragment.set(win, token);
  return token;
}

// The token for an <xml3d> element: its `token` attribute, else the page's fragment.
export function accessToken(xml3d, win) {
  const attr = (xml3d.getAttribute('token') || '').trim();
  return attr || takeFragmentToken(win);
}

// `url` with the token in its query (nothing added without a token).
export function withToken(url, token) {
  if (!token) return url;
  return `${url}${url.includes('?') ? '&' : '?'}${QUERY_KEY}=${encodeURIComponent(token)}`;
}

// `url` as shown on the page and in the console: the token replaced by '…'.
export function redact(url) {
  return String(url).replace(new RegExp(`([?&]${QUERY_KEY}=)[^&#]*`, 'g'), '$1…');
}
