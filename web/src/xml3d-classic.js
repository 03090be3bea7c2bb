// A classic-script entry for pages that cannot load the module directly: XHTML documents
// (application/xhtml+xml; XML3D 4.x pages often are: Chromium runs no module scripts in XML
// documents, crbug.com/717643) and pages that swap xml3d.js's <script src="xml3d.js"> for ours
// one to one. It loads xml3d.js from beside itself; the module then configures every <xml3d>
// as it does when loaded directly (at once when the document has already been parsed).
//
// When the pages' scripts see window.XML3D: xml3d.js is a classic script, so they could use it
// from DOMContentLoaded handlers (jQuery's ready: the examples' scriptValue calls
// setScriptValue there) and from window load handlers (the examples make their
// StandardCamera there). import() delays neither event, and those handlers threw "XML3D is
// not defined". So in an HTML document that is still being parsed, where this script runs
// from the parser, the entry writes a <script type="module"> into the document right after
// itself: a module script of the parser runs before DOMContentLoaded, as if the page had
// loaded the module itself. Elsewhere in an HTML document it appends one, which at least holds
// the load event back until it has run. XML documents run no module script element (and have
// no document.write), so there it is import(), and both events may come first. Inline
// scripts that use XML3D while the page is parsed still cannot (docs/web-client.md).
(function () {
  var self = document.currentScript;
  var url = new URL('xml3d.js', self && self.src ? self.src : location.href).href;
  var failed = function (e) { console.error('Tessera: could not load ' + url + (e ? ': ' + e : '')); };
  if (document.contentType !== 'text/html') {
    import(url).catch(failed);
    return;
  }
  var append = function () {
    var s = document.createElement('script');
    s.type = 'module';
    s.src = url;
    s.onerror = function () { failed(); };
    (document.head || document.documentElement).appendChild(s);
  };
  if (document.readyState === 'loading' && self && !self.async && !self.defer) {
    var mark = 'data-tessera-entry';
    document.write('<script type="module" ' + mark + ' src="' + url.replace(/&/g, '&amp;').replace(/"/g, '&quot;') + '"></script>');
    // A browser that ignored the write (a script it does not count as the parser's) gets the
    // appended element by DOMContentLoaded (this listener runs before the page's own).
    document.addEventListener('DOMContentLoaded', function () {
      if (!document.querySelector('script[' + mark + ']')) append();
    });
  } else {
    append();
  }
})();
