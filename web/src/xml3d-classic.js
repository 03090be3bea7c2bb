// A classic-script entry for pages that cannot load the module directly: XHTML documents
// (application/xhtml+xml; XML3D 4.x pages often are: Chromium runs no module scripts in XML
// documents, crbug.com/717643) and pages that swap xml3d.js's <script src="xml3d.js"> for ours
// one to one. It imports xml3d.js from beside itself; the module then configures every <xml3d>
// as it does when loaded directly (at once when the document has already been parsed).
(function () {
  var self = document.currentScript;
  var url = new URL('xml3d.js', self && self.src ? self.src : location.href).href;
  import(url).catch(function (e) { console.error('Tessera: could not load ' + url + ': ' + e); });
})();
