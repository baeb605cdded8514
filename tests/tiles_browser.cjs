// Loads a run's 3D Tiles (tileset.json, tiles/*.glb) in headless Chromium (Debian's, driven by
// playwright-core) with a real 3D Tiles client: NASA-AMMOS' 3d-tiles-renderer on three.js (npm,
// tools/node), as a web page would. A small HTTP server on 127.0.0.1 serves the run folder and
// the npm modules; the page frames the tileset, asks for every tile (error target 0: no tile is
// good enough to stand for its children) and renders until nothing is loading. Every request is
// recorded; anything not on that server is refused.
//
//   node tiles_browser.cjs --run RUN_FOLDER --node-modules DIR --chromium /usr/bin/chromium
//        --screenshot view.png [--timeout-ms 90000]
//
// With --page index.html instead of --run: imr's batch viewer page opened from disk, its tiles
// view (imr-tiles-viewer.js) left to load the first tiled run; only file:, blob: and data: URLs
// may be asked for; the result has tiles_shown and the same counts (tiles_requested: none, the
// page loads tiles from its own scripts), requested_far (what the page's first view asked for)
// and, zoomed out to 30 radii then at street level by the first leaf, visible_far and visible_near
// (the content uris drawn) and requested_near (asked for there; screenshots of both with
// --screenshot-far and --screenshot-near). With --click-tiles N instead: run N's "tiles" button
// clicked first, and buttons_disabled (each run's button, disabled when its run is shown).
//
// With --view far or --view near (levels of detail, issue 46): the renderer's own error target
// (16 px) instead of 0, and the camera 30 times the tileset's radius away (the whole drive, from
// far) or, near, a third of the first leaf's radius from it (street level). --error-target E sets
// the renderer's error target (pixels; a large one draws the coarsest level from any distance).
//
// Prints one JSON line: {ok, tileset_loaded, models_loaded, tiles_requested: [uris], load_errors,
// console_errors, requests_refused, http_errors, meshes, triangles, attributes, canvas}. Exit
// status 0 when ok, 1 otherwise.
'use strict';
const fs = require('fs');
const http = require('http');
const os = require('os');
const path = require('path');

function args() {
  const a = { timeoutMs: 90000 };
  const v = process.argv.slice(2);
  for (let i = 0; i < v.length; i += 2) {
    const key = v[i].replace(/^--/, '').replace(/-([a-z])/g, (_, c) => c.toUpperCase());
    a[key] = v[i + 1];
  }
  for (const k of [a.page ? 'page' : 'run', 'nodeModules', 'chromium', 'screenshot'])
    if (!a[k]) { console.error(`tiles_browser.cjs: --${k} is required`); process.exit(2); }
  a.timeoutMs = Number(a.timeoutMs);
  return a;
}

const PAGE = (view, errorTarget) => `<!doctype html>
<html><head><meta charset="utf-8"><title>imr tiles</title>
<style>html,body{margin:0;height:100%;background:#f0f0f0}canvas{display:block}</style>
<script type="importmap">{"imports": {
  "three": "/node_modules/three/build/three.module.js",
  "three/addons/": "/node_modules/three/examples/jsm/",
  "3d-tiles-renderer/three": "/node_modules/3d-tiles-renderer/build/index.three.js"}}</script>
</head><body>
<script type="module">
import * as THREE from 'three';
import { TilesRenderer } from '3d-tiles-renderer/three';
const state = window.__imr = { tilesetLoaded: false, models: 0, loadErrors: [], meshes: 0,
                               triangles: 0, attributes: [], done: false };
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setSize(1000, 700);
renderer.setClearColor(0xf0f0f0);
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.add(new THREE.HemisphereLight(0xffffff, 0x606060, 2.5));
const camera = new THREE.PerspectiveCamera(50, 1000 / 700, 0.1, 100000);
const tiles = new TilesRenderer('/run/tileset.json');
const VIEW = ${JSON.stringify(view || '')};
if (!VIEW) tiles.errorTarget = 0;
if (${JSON.stringify(errorTarget !== undefined)}) tiles.errorTarget = ${Number(errorTarget)};
// 3D Tiles is z-up, three.js y-up.
tiles.group.rotation.x = -Math.PI / 2;
scene.add(tiles.group);
tiles.setCamera(camera);
tiles.setResolutionFromRenderer(camera, renderer);
// The camera is placed once the tileset is read (near: once the first leaf is found, which may
// take reading external tilesets); the renderer asks for nothing before.
let seen = false, placed = false;
tiles.addEventListener('load-root-tileset', async () => {
  seen = true;
  tiles.group.updateMatrixWorld(true);
  const sphere = new THREE.Sphere();
  tiles.getBoundingSphere(sphere);
  sphere.applyMatrix4(tiles.group.matrixWorld);
  // From above and a little to the side, the whole tileset in view (far: from 30 radii).
  let distance = sphere.radius * (VIEW === 'far' ? 30 : 2.4);
  if (VIEW === 'near') {
    // The first leaf (a tile_ content) in tree order, from a third of its radius; levels of
    // detail's subtrees (external tilesets, their uris relative to tiles/) read on the way.
    const find = async (t, base) => {
      if (t.content && t.content.uri.includes('tile_')) return t;
      if (t.content && /\.json$/.test(t.content.uri)) {
        const sub = await (await fetch('/run/' + base + t.content.uri)).json();
        const f = await find(sub.root, 'tiles/');
        if (f) return f;
      }
      for (const c of t.children || []) { const f = await find(c, base); if (f) return f; }
      return null;
    };
    // Its box (the tileset's, under the root's transform; not yet preprocessed by the renderer).
    const leaf = await find(tiles.root, ''), box = leaf.boundingVolume.box;
    const toWorld = new THREE.Matrix4().fromArray(tiles.root.transform || new THREE.Matrix4().elements)
      .premultiply(tiles.group.matrixWorld);
    sphere.center.set(box[0], box[1], box[2]).applyMatrix4(toWorld);
    sphere.radius = Math.hypot(...box.slice(3));
    distance = sphere.radius / 3;
  }
  camera.position.copy(sphere.center).add(new THREE.Vector3(0.3, 1.0, 0.6).normalize().multiplyScalar(distance));
  camera.lookAt(sphere.center);
  camera.updateMatrixWorld();
  placed = true;
  state.tilesetLoaded = true;
});
tiles.addEventListener('load-model', (e) => {
  state.models += 1;
  e.scene.traverse((o) => {
    if (!o.isMesh) return;
    state.meshes += 1;
    const g = o.geometry;
    state.triangles += (g.index ? g.index.count : g.attributes.position.count) / 3;
    for (const name of Object.keys(g.attributes)) if (!state.attributes.includes(name)) state.attributes.push(name);
    if (!g.attributes.color && !(o.material && o.material.map)) o.material = new THREE.MeshStandardMaterial({ color: 0xd07030, side: THREE.DoubleSide });
  });
});
tiles.addEventListener('load-error', (e) => state.loadErrors.push(String(e.url) + ': ' + String(e.error && e.error.message || e.error)));
let quiet = 0;
function frame() {
  camera.updateMatrixWorld();
  if (placed || !seen) tiles.update();
  renderer.render(scene, camera);
  const stats = tiles.stats || {};
  const busy = (stats.downloading || 0) + (stats.parsing || 0);
  quiet = state.tilesetLoaded && busy === 0 ? quiet + 1 : 0;
  if (quiet > 30) { state.done = true; return; }
  requestAnimationFrame(frame);
}
requestAnimationFrame(frame);
</script></body></html>`;

function serve(run, nodeModules, view, errorTarget) {
  const types = { '.json': 'application/json', '.glb': 'model/gltf-binary', '.js': 'text/javascript',
                  '.html': 'text/html', '.map': 'application/json' };
  const server = http.createServer((req, res) => {
    const url = decodeURIComponent(req.url.split('?')[0]);
    let file = null;
    if (url === '/' || url === '/index.html') { res.writeHead(200, { 'content-type': 'text/html' }); res.end(PAGE(view, errorTarget)); return; }
    if (url.startsWith('/run/')) file = path.join(run, url.slice(5));
    else if (url.startsWith('/node_modules/')) file = path.join(nodeModules, url.slice(14));
    const inside = file && (file.startsWith(path.resolve(run) + path.sep) || file.startsWith(path.resolve(nodeModules) + path.sep));
    if (!inside || !fs.existsSync(file) || !fs.statSync(file).isFile()) { res.writeHead(404); res.end(); return; }
    res.writeHead(200, { 'content-type': types[path.extname(file)] || 'application/octet-stream' });
    fs.createReadStream(file).pipe(res);
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

// Headless Chromium with a page whose errors go to `result` and whose requests pass `allowed`
// (the others are refused and listed).
async function openPage(a, profile, viewport, result, allowed) {
  const { chromium } = require(path.join(path.resolve(a.nodeModules), 'playwright-core'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: a.chromium, headless: true, viewport,
    args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
           '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  const page = context.pages()[0] || await context.newPage();
  page.on('console', (m) => { if (m.type() === 'error') result.console_errors.push(m.text()); });
  page.on('pageerror', (e) => result.console_errors.push('uncaught: ' + e.message));
  await page.route('**/*', (route) => {
    const url = route.request().url();
    if (allowed(url)) return route.continue();
    result.requests_refused.push(url);
    return route.abort();
  });
  return { context, page };
}

// The batch viewer page from disk: its tiles view.
async function viewerPage(a) {
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'imr-chromium-'));
  const result = { ok: false, tileset_loaded: false, models_loaded: 0, tiles_shown: null, load_errors: [],
                   console_errors: [], requests_refused: [], canvas: null };
  let context;
  try {
    let page;
    ({ context, page } = await openPage(a, profile, { width: 1280, height: 1000 }, result,
                                        (url) => /^(file|blob|data):/.test(url)));
    await page.goto('file://' + path.resolve(a.page));
    let timeout = null;
    await page.waitForFunction(() => window.imrTilesViewer && window.imrTilesViewer.done, null, { timeout: a.timeoutMs })
      .catch((e) => { timeout = 'not done: ' + e.message; });
    if (a.clickTiles !== undefined) {
      // The run's "tiles" button: the view switches to it.
      await page.click(`button[data-tiles="${a.clickTiles}"]`);
      await page.waitForFunction((n) => window.imrTilesViewer.shown === n && window.imrTilesViewer.done,
                                 Number(a.clickTiles), { timeout: a.timeoutMs })
        .catch((e) => { timeout = 'after the click: ' + e.message; });
      result.buttons_disabled = await page.evaluate(() =>
        Array.from(document.querySelectorAll('button[data-tiles]'), (b) => b.disabled));
    }
    const s = await page.evaluate(() => window.imrTilesViewer || null);
    if (!s) throw new Error('the page has no tiles view (window.imrTilesViewer)');
    result.requested_far = s.requested.slice();
    result.tileset_loaded = s.tilesetLoaded;
    result.models_loaded = s.models;
    result.tiles_shown = s.shown;
    result.local = Boolean(s.local);
    result.load_errors = s.errors.concat(timeout ? [timeout] : []);
    const canvas = page.locator('#tiles-viewer canvas');
    await canvas.scrollIntoViewIfNeeded();
    const box = await canvas.boundingBox();
    result.canvas = box && { width: Math.round(box.width), height: Math.round(box.height) };
    await canvas.screenshot({ path: a.screenshot });
    // Then zoomed out to 30 radii, and at street level by the first leaf: what it draws.
    const settle = async (what) => {
      await page.waitForFunction(() => window.imrTilesViewer.done, null, { timeout: a.timeoutMs })
        .catch((e) => { result.load_errors.push(what + ': not done: ' + e.message); });
    };
    if (a.clickTiles === undefined && await page.evaluate(() => window.imrTilesViewer.farView !== undefined)) {
      await page.evaluate(() => window.imrTilesViewer.farView(30));
      await settle('far');
      result.visible_far = await page.evaluate(() => window.imrTilesViewer.visible());
      if (a.screenshotFar) await canvas.screenshot({ path: a.screenshotFar });
      const before = (await page.evaluate(() => window.imrTilesViewer.requested)).length;
      await page.evaluate(() => window.imrTilesViewer.nearLeaf());
      await settle('near');
      const n = await page.evaluate(() => window.imrTilesViewer);
      result.requested_near = n.requested.slice(before);
      result.visible_near = await page.evaluate(() => window.imrTilesViewer.visible());
      result.load_errors = result.load_errors.concat(n.errors.slice(s.errors.length));
      if (a.screenshotNear) await canvas.screenshot({ path: a.screenshotNear });
    }
    result.ok = result.tileset_loaded && result.models_loaded > 0 && result.load_errors.length === 0 &&
                result.console_errors.length === 0 && result.requests_refused.length === 0;
  } catch (e) {
    result.load_errors.push(String(e && e.message || e));
  } finally {
    if (context) await context.close().catch(() => {});
    fs.rmSync(profile, { recursive: true, force: true });
  }
  return result;
}

(async () => {
  const a = args();
  if (a.page) {
    const r = await viewerPage(a);
    console.log(JSON.stringify(r));
    process.exit(r.ok ? 0 : 1);
  }
  a.run = path.resolve(a.run);
  a.nodeModules = path.resolve(a.nodeModules);
  const server = await serve(a.run, a.nodeModules, a.view, a.errorTarget);
  const origin = `http://127.0.0.1:${server.address().port}`;
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'imr-chromium-'));
  const result = { ok: false, tileset_loaded: false, models_loaded: 0, tiles_requested: [],
                   load_errors: [], console_errors: [], requests_refused: [], http_errors: [],
                   meshes: 0, triangles: 0, attributes: [], canvas: null };
  let context;
  try {
    let page;
    ({ context, page } = await openPage(a, profile, { width: 1000, height: 700 }, result,
                                        (url) => url.startsWith(origin + '/') || /^(blob|data):/.test(url)));
    page.on('response', (r) => {
      const url = r.url();
      if (!url.startsWith(origin)) return;
      if (r.status() !== 200) result.http_errors.push(url + ': ' + r.status());
      const m = url.match(/\/run\/(tiles\/(tile|lod)_[0-9]+\.glb)$/);
      if (m && r.status() === 200) result.tiles_requested.push(m[1]);
    });
    await page.goto(origin + '/index.html');
    let timeout = null;
    await page.waitForFunction(() => window.__imr && window.__imr.done, null, { timeout: a.timeoutMs })
      .catch((e) => { timeout = 'not done: ' + e.message; });
    const s = await page.evaluate(() => window.__imr);
    if (timeout) s.loadErrors.push(timeout);
    result.tileset_loaded = s.tilesetLoaded;
    result.models_loaded = s.models;
    result.load_errors = s.loadErrors;
    result.meshes = s.meshes;
    result.triangles = s.triangles;
    result.attributes = s.attributes.sort();
    result.tiles_requested.sort();
    const canvas = page.locator('canvas');
    const box = await canvas.boundingBox();
    result.canvas = box && { width: Math.round(box.width), height: Math.round(box.height) };
    await canvas.screenshot({ path: a.screenshot });
    result.ok = result.tileset_loaded && result.models_loaded > 0 && result.load_errors.length === 0 &&
                result.console_errors.length === 0 && result.requests_refused.length === 0 &&
                result.http_errors.length === 0;
  } catch (e) {
    result.load_errors.push(String(e && e.message || e));
  } finally {
    if (context) await context.close().catch(() => {});
    server.close();
    fs.rmSync(profile, { recursive: true, force: true });
  }
  console.log(JSON.stringify(result));
  process.exit(result.ok ? 0 : 1);
})();
