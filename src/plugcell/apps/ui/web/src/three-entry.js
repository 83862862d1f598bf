// What the UI's 3-D view (static/js/view3d.js) takes from three.js: bundled, minified, as one
// ES module (build.mjs); nothing is fetched from the Internet at run time.  Only the names the
// view uses, so that esbuild leaves the rest of three out.
export {
  ArrowHelper, AxesHelper, Box3, BufferAttribute, BufferGeometry, Color, CylinderGeometry,
  DirectionalLight, GridHelper, Group, HemisphereLight, Line, LineBasicMaterial, Matrix4, Mesh,
  MeshStandardMaterial, PerspectiveCamera, Points, PointsMaterial, REVISION, Scene, Vector2,
  Vector3, WebGLRenderer,
} from "three";
export { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
