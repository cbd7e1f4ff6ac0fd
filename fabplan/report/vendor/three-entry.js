export { Scene, PerspectiveCamera, WebGLRenderer, BufferGeometry, BufferAttribute, Mesh,
  MeshLambertMaterial, LineSegments, LineLoop, LineBasicMaterial, AmbientLight, DirectionalLight,
  HemisphereLight, Raycaster, Vector2, Vector3, Color, Box3, Sphere, DoubleSide } from 'three';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
