// The batch viewer page's view of tiled runs (issue 32; viewer_page.h): NASA-AMMOS'
// 3d-tiles-renderer on three.js (npm, tools/node), bundled by esbuild at build time into
// imr-tiles-viewer.js (one classic script, as a page opened from disk can only load those).
//
// The page works from file://, where fetch() of local files is refused: a run's tileset.json and
// each tile are written beside the page as scripts (assets/tiles/<n>/<name>.js, the bytes in
// base64 behind imrTileData(n, path, base64)), and a renderer plugin answers the renderer's
// requests for https://imr-tiles.invalid/<n>/<path> by loading that script when the tile is
// first needed: nothing is fetched from the network, and tiles out of view are never loaded.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { TilesRenderer } from '3d-tiles-renderer/three';

const BASE = 'https://imr-tiles.invalid/';

(function () {
  const table = document.getElementById('imr-tiles');
  const host = document.getElementById('tiles-viewer');
  const status = document.getElementById('tiles-status');
  if (!table || !host) return;
  const runs = JSON.parse(table.textContent);
  // For tests and the curious: what the view has done.
  // requested: the tiles asked for, in order (levels of detail far away, leaves near);
  // nearLeaf(): the camera to street level at the first leaf (for tests).
  const state = window.imrTilesViewer = { shown: null, tilesetLoaded: false, models: 0, errors: [],
                                          done: false, show: null, requested: [], nearLeaf: null };
  const say = (text) => { if (status) status.textContent = text; };

  const waiting = {};  // "<n>/<path>" -> [[resolve, reject], ...] (the renderer, nearLeaf)
  window.imrTileData = function (n, path, b64) {
    const key = n + '/' + path;
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let k = 0; k < bin.length; ++k) bytes[k] = bin.charCodeAt(k);
    if (waiting[key]) { for (const w of waiting[key]) w[0](bytes); delete waiting[key]; }
  };
  function embedded(n, path) {
    return new Promise((resolve, reject) => {
      const run = runs[n];
      // A level of detail's subtree (tiles/lod_NNNNNN.json) is in lod_NNNNNN_tree.js.
      const name = path === 'tileset.json' ? 'tileset'
        : path.replace(/^tiles\//, '').replace(/\.glb$/, '').replace(/^(lod_[0-9]{6})\.json$/, '$1_tree');
      if (!run || !/^(tileset|tile_[0-9]{6}|lod_[0-9]{6}(_tree)?)$/.test(name)) { reject(new Error('not a tile of this page: ' + path)); return; }
      const key = n + '/' + path;
      if (waiting[key]) { waiting[key].push([resolve, reject]); return; }  // its script is on its way
      waiting[key] = [[resolve, reject]];
      state.requested.push(path);
      const s = document.createElement('script');
      s.src = run.scripts + '/' + name + '.js';
      s.onerror = () => {
        for (const w of waiting[key] || []) w[1](new Error('cannot load ' + s.src));
        delete waiting[key];
      };
      document.head.appendChild(s);
    });
  }
  // A 3d-tiles-renderer plugin: every request of the renderer answered from the page's scripts.
  class EmbeddedTilesPlugin {
    constructor(n) { this.name = 'IMR_EMBEDDED_TILES'; this.n = n; }
    fetchData(url) {
      const prefix = BASE + this.n + '/';
      if (!url.startsWith(prefix)) return Promise.reject(new Error('not a tile of this page: ' + url));
      const path = url.slice(prefix.length).split('?')[0];
      return embedded(this.n, path).then((bytes) => new Response(bytes, {
        status: 200, headers: { 'content-type': path.endsWith('.json') ? 'application/json' : 'model/gltf-binary' } }));
    }
  }

  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0xeef1f4);
  host.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x707070, 2.2));
  const sun = new THREE.DirectionalLight(0xffffff, 1.2);
  sun.position.set(1, 3, 2);
  scene.add(sun);
  const camera = new THREE.PerspectiveCamera(50, 1, 0.1, 1e6);
  const controls = new OrbitControls(camera, renderer.domElement);
  const plain = new THREE.MeshStandardMaterial({ color: 0xeba64d, roughness: 0.8, side: THREE.DoubleSide });
  let tiles = null;
  let quiet = 0;
  let radius = 1;  // the tileset's bounding sphere's

  function resize() {
    const w = host.clientWidth || 800, h = host.clientHeight || 520;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    if (tiles) tiles.setResolutionFromRenderer(camera, renderer);
  }

  function show(n) {
    const run = runs[n];
    if (!run) return;
    if (tiles) { scene.remove(tiles.group); tiles.dispose(); }
    Object.assign(state, { shown: n, tilesetLoaded: false, models: 0, done: false, local: false });
    quiet = 0;
    document.querySelectorAll('button[data-tiles]').forEach((b) => { b.disabled = Number(b.dataset.tiles) === n; });
    say('Loading the tiles of ' + run.name + ' ...');
    tiles = new TilesRenderer(BASE + n + '/tileset.json');
    tiles.registerPlugin(new EmbeddedTilesPlugin(n));
    tiles.group.rotation.x = -Math.PI / 2;  // 3D Tiles is z-up, three.js y-up
    scene.add(tiles.group);
    tiles.setCamera(camera);
    resize();
    tiles.addEventListener('load-root-tileset', (e) => {
      state.tilesetLoaded = true;
      // A geo-referenced run (output.tiles.origin) stands in ECEF, up along the Earth's normal
      // there: shown in its local frame (asset.extras.imr.local_transform), ground down, as
      // without an origin.
      const ts = e.tileset || {};
      const imr = ts.asset && ts.asset.extras && ts.asset.extras.imr;
      if (imr && Array.isArray(imr.local_transform) && ts.root && Array.isArray(ts.root.transform)) {
        const back = new THREE.Matrix4().fromArray(imr.local_transform)
          .multiply(new THREE.Matrix4().fromArray(ts.root.transform).invert());
        tiles.group.matrixAutoUpdate = false;
        tiles.group.matrix.makeRotationX(-Math.PI / 2).multiply(back);
        state.local = true;
      }
      tiles.group.updateMatrixWorld(true);
      const sphere = new THREE.Sphere();
      tiles.getBoundingSphere(sphere);
      sphere.applyMatrix4(tiles.group.matrixWorld);
      controls.target.copy(sphere.center);
      camera.position.copy(sphere.center).add(new THREE.Vector3(0.3, 1.0, 0.6).normalize().multiplyScalar(sphere.radius * 2.2));
      radius = Math.max(sphere.radius, 1e-3);
      controls.update();
    });
    tiles.addEventListener('load-model', (e) => {
      state.models += 1;
      e.scene.traverse((o) => {
        if (o.isMesh && !o.geometry.attributes.color && !(o.material && o.material.map)) o.material = plain;
        else if (o.isMesh && o.material) o.material.side = THREE.DoubleSide;
      });
      say(run.name + ': ' + state.models + ' of ' + run.tiles + ' tiles loaded (' + run.triangles +
          ' triangles in all). Drag to turn, scroll to zoom, right-drag to pan.');
    });
    tiles.addEventListener('load-error', (e) => {
      state.errors.push(String(e.url) + ': ' + String(e.error && e.error.message || e.error));
      say('Could not load ' + String(e.url));
    });
  }
  state.show = show;
  // The camera `k` radii from the target, as it looks now (zoomed out: the levels of detail).
  state.farView = function (k) {
    const away = camera.position.clone().sub(controls.target).normalize();
    camera.position.copy(controls.target).addScaledVector(away, radius * k);
    controls.update();
    quiet = 0;
    state.done = false;
  };
  // The content drawn now, as paths in the run folder (uris in a level of detail's subtree are
  // relative to tiles/).
  const runPath = (t) => {
    const prefix = BASE + state.shown + '/';
    const u = new URL(t.content.uri, ((t.internal && t.internal.basePath) || BASE + state.shown) + '/').toString();
    return u.startsWith(prefix) ? u.slice(prefix.length) : u;
  };
  state.visible = () => Array.from((tiles && tiles.visibleTiles) || [], (t) => t.content && t.content.uri && runPath(t)).filter(Boolean);
  state.nearLeaf = async function () {
    const n = state.shown;
    // The first leaf in tree order; a level of detail's subtree (an external tileset) is walked
    // as the renderer loaded it, or read when it has not.
    const find = async (t, base) => {
      const uri = t.content && t.content.uri;
      if (uri && /(^|\/)tile_[0-9]{6}\.glb$/.test(uri)) return t;
      let children = t.children || [];
      if (uri && /\.json$/.test(uri)) {
        if (!children.length) children = [JSON.parse(new TextDecoder().decode(await embedded(n, base + uri))).root];
        base = (base + uri).replace(/[^/]*$/, '');
      }
      for (const c of children) { const f = await find(c, base); if (f) return f; }
      return null;
    };
    const leaf = tiles && tiles.root && await find(tiles.root, '');
    if (!leaf) return false;
    // Its box (the tileset's, under the root's transform; not yet preprocessed by the renderer).
    const box = leaf.boundingVolume.box;
    const toWorld = new THREE.Matrix4().fromArray(tiles.root.transform || new THREE.Matrix4().elements)
      .premultiply(tiles.group.matrixWorld);
    const sphere = new THREE.Sphere(new THREE.Vector3(box[0], box[1], box[2]).applyMatrix4(toWorld),
                                    Math.hypot(...box.slice(3)));
    controls.target.copy(sphere.center);
    camera.position.copy(sphere.center).add(new THREE.Vector3(0.3, 1.0, 0.6).normalize().multiplyScalar(sphere.radius / 3));
    controls.update();
    quiet = 0;
    state.done = false;
    return true;
  };

  function frame() {
    requestAnimationFrame(frame);
    if (!tiles) return;
    controls.update();
    // Near and far planes around what is in view, however far it is zoomed out (a fixed far
    // plane of 20 radii left the view empty beyond it).
    const d = camera.position.distanceTo(controls.target);
    camera.near = Math.max(Math.min(radius / 1000, d / 100), 0.01);
    camera.far = d + 4 * radius;
    camera.updateProjectionMatrix();
    camera.updateMatrixWorld();
    tiles.update();
    renderer.render(scene, camera);
    const s = tiles.stats || {};
    quiet = state.tilesetLoaded && (s.downloading || 0) + (s.parsing || 0) === 0 ? quiet + 1 : 0;
    state.done = quiet > 30;
  }
  window.addEventListener('resize', resize);
  document.querySelectorAll('button[data-tiles]').forEach((b) => b.addEventListener('click', () => {
    show(Number(b.dataset.tiles));
    host.scrollIntoView({ behavior: 'smooth' });
  }));
  const first = runs.findIndex((r) => r !== null);
  if (first >= 0) show(first);
  requestAnimationFrame(frame);
})();
