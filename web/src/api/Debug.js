// XML3D.debug (XML3D 5: logDebug, logInfo, logWarning, logError, logException) and the
// one-warning-per-thing helper the API uses for what Tessera does not support. Nothing here
// throws: a page's logging call must never stop its script.

const LEVELS = { all: 0, debug: 1, info: 2, warning: 3, error: 4, exception: 5, none: 6 };

export const debug = {
  ALL: 0, DEBUG: 1, INFO: 2, WARNING: 3, ERROR: 4, EXCEPTION: 5,
  /** Messages below this level are dropped (XML3D option "loglevel", default warning). */
  loglevel: LEVELS.warning,
  setLogLevel(level) {
    const v = typeof level === 'number' ? level : LEVELS[String(level).toLowerCase()];
    if (v !== undefined) this.loglevel = v;
  },
  log(level, args) {
    if (level < this.loglevel) return;
    try {
      const c = globalThis.console;
      const fn = level >= LEVELS.error ? c.error : level === LEVELS.warning ? c.warn : level === LEVELS.info ? c.info : c.debug;
      fn.call(c, 'XML3D:', ...args);
    } catch { /* logging never throws */ }
  },
  logDebug(...a) { this.log(LEVELS.debug, a); },
  logInfo(...a) { this.log(LEVELS.info, a); },
  logWarning(...a) { this.log(LEVELS.warning, a); },
  logError(...a) { this.log(LEVELS.error, a); },
  logException(...a) { this.log(LEVELS.exception, a); },
  /** xml3d.js also has assert(condition, message): logs an error when the condition is false. */
  assert(cond, ...a) { if (!cond) this.log(LEVELS.error, ['assertion failed:', ...a]); },
};
for (const k of ['logDebug', 'logInfo', 'logWarning', 'logError', 'logException', 'assert', 'setLogLevel', 'log'])
  debug[k] = debug[k].bind(debug);

const warned = new Set();
/** One console warning per key for the page's lifetime ("XML3D: <message>"). */
export function warnOnce(key, message = key) {
  if (warned.has(key)) return;
  warned.add(key);
  try { globalThis.console.warn(`XML3D: ${message}`); } catch { /* never throws */ }
}
