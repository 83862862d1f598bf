// What the UI's 3-D view (static/js/view3d.js) takes from three.js: bundled, minified, as one
// ES module (build.mjs); nothing is fetched from the Internet at run time.
export * from "three";
export { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
