// Loads a geo-referenced run's 3D Tiles in CesiumJS (npm `cesium`, tools/node) in headless
// Chromium (Debian's, driven by playwright-core), from a small HTTP server on 127.0.0.1 that
// serves the run folder and the npm modules; any other request is refused.
//
// Where Cesium puts the tileset: `Cesium3DTileset.fromUrl` (no canvas needed), its
// boundingSphere's centre as a cartographic, against where Cesium's own maths puts the centre of
// the tileset's root box: Transforms.headingPitchRollToFixedFrame at the origin the tileset says
// (asset.extras.imr.origin: latitude, longitude, height, heading) applied to the root box's
// centre in the local frame (asset.extras.imr.local_transform). Cesium's heading turns the
// local +X from east and +Y from north clockwise, imr's convention for the local +Y. Then a
// CesiumWidget (no globe, no imagery: nothing asked of the network) renders the tileset
// with every tile asked for (maximumScreenSpaceError 0) until all have loaded.
//
//   node cesium_browser.cjs --run RUN_FOLDER --node-modules DIR --chromium /usr/bin/chromium
//        --screenshot view.png [--timeout-ms 90000]
//
// Prints one JSON line: {ok, loaded, origin, center, expected, horizontal_m, height_m,
// origin_ecef_m, radius, webgl, tiles_loaded, tiles_failed, console_errors, requests_refused,
// http_errors, load_errors}. Exit status 0 when ok (loaded, nothing refused or failed), 1
// otherwise; the caller asserts the distances.
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
  for (const k of ['run', 'nodeModules', 'chromium', 'screenshot'])
    if (!a[k]) { console.error(`cesium_browser.cjs: --${k} is required`); process.exit(2); }
  a.timeoutMs = Number(a.timeoutMs);
  return a;
}

const PAGE = `<!doctype html>
<html><head><meta charset="utf-8"><title>imr tiles in CesiumJS</title>
<style>html,body,#view{margin:0;width:100%;height:100%;background:#f0f0f0}</style>
<script>window.CESIUM_BASE_URL = '/node_modules/cesium/Build/Cesium/';</script>
<script src="/node_modules/cesium/Build/Cesium/Cesium.js"></script>
<link rel="stylesheet" href="/node_modules/cesium/Build/Cesium/Widgets/widgets.css">
</head><body><div id="view"></div>
<script>
const state = window.__imr = { loaded: false, done: false, errors: [], tilesLoaded: 0, tilesFailed: [],
                               webgl: false };
(async () => {
  try {
    const url = '/run/tileset.json';
    const json = await (await fetch(url)).json();
    const imr = json.asset.extras.imr;
    const tileset = await Cesium.Cesium3DTileset.fromUrl(url, { maximumScreenSpaceError: 0 });
    state.loaded = true;
    const sphere = tileset.boundingSphere;
    const centre = Cesium.Cartographic.fromCartesian(sphere.center);
    state.radius = sphere.radius;
    state.center = { latitude: Cesium.Math.toDegrees(centre.latitude),
                     longitude: Cesium.Math.toDegrees(centre.longitude), height: centre.height };
    if (imr.origin) {
      const o = imr.origin;
      state.origin = o;
      const at = Cesium.Cartesian3.fromDegrees(o.longitude, o.latitude, o.height);
      const frame = Cesium.Transforms.headingPitchRollToFixedFrame(
          at, new Cesium.HeadingPitchRoll(Cesium.Math.toRadians(o.heading), 0, 0));
      const box = json.root.boundingVolume.box;
      const local = Cesium.Matrix4.multiplyByPoint(Cesium.Matrix4.fromArray(imr.local_transform),
                                                   new Cesium.Cartesian3(box[0], box[1], box[2]),
                                                   new Cesium.Cartesian3());
      const want = Cesium.Matrix4.multiplyByPoint(frame, local, new Cesium.Cartesian3());
      const expected = Cesium.Cartographic.fromCartesian(want);
      state.expected = { latitude: Cesium.Math.toDegrees(expected.latitude),
                         longitude: Cesium.Math.toDegrees(expected.longitude), height: expected.height };
      state.horizontal_m = new Cesium.EllipsoidGeodesic(
          new Cesium.Cartographic(centre.longitude, centre.latitude, 0),
          new Cesium.Cartographic(expected.longitude, expected.latitude, 0)).surfaceDistance;
      state.height_m = centre.height - expected.height;
      // The local origin as the root transform puts it, against Cesium's fromDegrees.
      const t = json.root.transform;
      state.origin_ecef_m = Cesium.Cartesian3.distance(new Cesium.Cartesian3(t[12], t[13], t[14]), at);
    }
    // Drawn: a widget without globe, imagery or sky (nothing from the network).
    let widget;
    try {
      widget = new Cesium.CesiumWidget('view', { baseLayer: false, globe: false, skyBox: false,
                                                 skyAtmosphere: false, requestRenderMode: false,
                                                 contextOptions: { webgl: { preserveDrawingBuffer: true } } });
      state.webgl = true;
    } catch (e) {
      state.errors.push('no WebGL: ' + String(e && e.message || e));
      state.done = true;
      return;
    }
    widget.scene.backgroundColor = Cesium.Color.fromCssColorString('#f0f0f0');
    tileset.tileLoad.addEventListener(() => { state.tilesLoaded += 1; });
    tileset.tileFailed.addEventListener((e) => state.tilesFailed.push(String(e.url) + ': ' + String(e.message)));
    widget.scene.primitives.add(tileset);
    widget.camera.viewBoundingSphere(sphere, new Cesium.HeadingPitchRange(0.3, -0.9, sphere.radius * 2.5));
    widget.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);
    let quiet = 0;
    const tick = () => {
      quiet = tileset.tilesLoaded ? quiet + 1 : 0;
      if (quiet > 20) { state.done = true; return; }
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  } catch (e) {
    state.errors.push(String(e && e.stack || e));
    state.done = true;
  }
})();
</script></body></html>`;

function serve(run, nodeModules) {
  const types = { '.json': 'application/json', '.glb': 'model/gltf-binary', '.js': 'text/javascript',
                  '.html': 'text/html', '.css': 'text/css', '.wasm': 'application/wasm', '.svg': 'image/svg+xml',
                  '.png': 'image/png' };
  const server = http.createServer((req, res) => {
    const url = decodeURIComponent(req.url.split('?')[0]);
    let file = null;
    if (url === '/' || url === '/index.html') { res.writeHead(200, { 'content-type': 'text/html' }); res.end(PAGE); return; }
    if (url.startsWith('/run/')) file = path.join(run, url.slice(5));
    else if (url.startsWith('/node_modules/')) file = path.join(nodeModules, url.slice(14));
    const inside = file && (file.startsWith(run + path.sep) || file.startsWith(nodeModules + path.sep));
    if (!inside || !fs.existsSync(file) || !fs.statSync(file).isFile()) { res.writeHead(404); res.end(); return; }
    res.writeHead(200, { 'content-type': types[path.extname(file)] || 'application/octet-stream' });
    fs.createReadStream(file).pipe(res);
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

(async () => {
  const a = args();
  a.run = path.resolve(a.run);
  a.nodeModules = path.resolve(a.nodeModules);
  const server = await serve(a.run, a.nodeModules);
  const origin = `http://127.0.0.1:${server.address().port}`;
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'imr-chromium-'));
  const result = { ok: false, loaded: false, console_errors: [], requests_refused: [], http_errors: [],
                   load_errors: [] };
  let context;
  try {
    const { chromium } = require(path.join(a.nodeModules, 'playwright-core'));
    context = await chromium.launchPersistentContext(profile, {
      executablePath: a.chromium, headless: true, viewport: { width: 1000, height: 700 },
      // WebGL without a GPU: SwiftShader, which Chromium no longer picks by itself.
      args: ['--no-sandbox', '--use-gl=angle', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
             '--disable-quic', '--no-first-run', '--disable-background-networking',
             '--disable-component-update', '--disable-sync'],
    });
    const page = context.pages()[0] || await context.newPage();
    page.on('console', (m) => { if (m.type() === 'error') result.console_errors.push(m.text()); });
    page.on('pageerror', (e) => result.console_errors.push('uncaught: ' + e.message));
    page.on('response', (r) => { if (r.url().startsWith(origin) && r.status() !== 200) result.http_errors.push(r.url() + ': ' + r.status()); });
    await page.route('**/*', (route) => {
      const url = route.request().url();
      if (url.startsWith(origin + '/') || /^(blob|data):/.test(url)) return route.continue();
      result.requests_refused.push(url);
      return route.abort();
    });
    await page.goto(origin + '/index.html');
    let timeout = null;
    await page.waitForFunction(() => window.__imr && window.__imr.done, null, { timeout: a.timeoutMs })
      .catch((e) => { timeout = 'not done: ' + e.message; });
    const s = await page.evaluate(() => window.__imr);
    for (const k of ['loaded', 'origin', 'center', 'expected', 'horizontal_m', 'height_m', 'origin_ecef_m',
                     'radius', 'webgl'])
      result[k] = s[k] === undefined ? null : s[k];
    result.tiles_loaded = s.tilesLoaded;
    result.tiles_failed = s.tilesFailed;
    result.load_errors = s.errors.concat(timeout ? [timeout] : []);
    await page.screenshot({ path: a.screenshot });
    result.ok = result.loaded && result.load_errors.length === 0 && result.tiles_failed.length === 0 &&
                result.requests_refused.length === 0 && result.http_errors.length === 0;
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
