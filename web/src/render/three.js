// three.js, loaded as an ES module straight from web/node_modules (no build step, no import map).
export * from '../../node_modules/three/build/three.module.js';
