// Opens imr's batch viewer page in headless Chromium (Debian's, driven by playwright-core) and
// checks it as a person would see it: <model-viewer> fires `load` for the first mesh, every
// image on the page loads, nothing is fetched from the network (only file:, blob:, data: URLs),
// and the console stays free of errors. Saves a screenshot of the page and one of the 3D view.
//
//   node viewer_browser.cjs --page index.html --node-modules DIR --chromium /usr/bin/chromium
//        --screenshot page.png --viewer-screenshot viewer.png [--timeout-ms 60000]
//
// Prints one JSON line: {ok, loads, shown, errors: [...], console_errors: [...], requests_refused:
// [...], images: {total, loaded}, viewer: {width, height}, textures (materials with a loaded base
// colour texture), blob_requests: {started, finished, failed: [...]}}. Exit status 0 when ok, 1
// otherwise.
'use strict';
const fs = require('fs');
const os = require('os');
const path = require('path');

function args() {
  const a = { timeoutMs: 60000 };
  const v = process.argv.slice(2);
  for (let i = 0; i < v.length; i += 2) {
    const key = v[i].replace(/^--/, '').replace(/-([a-z])/g, (_, c) => c.toUpperCase());
    a[key] = v[i + 1];
  }
  for (const k of ['page', 'nodeModules', 'chromium', 'screenshot', 'viewerScreenshot'])
    if (!a[k]) { console.error(`viewer_browser.cjs: --${k} is required`); process.exit(2); }
  a.timeoutMs = Number(a.timeoutMs);
  return a;
}

(async () => {
  const a = args();
  const { chromium } = require(path.join(a.nodeModules, 'playwright-core'));
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'imr-chromium-'));
  const result = { ok: false, loads: 0, shown: null, errors: [], console_errors: [],
                   requests_refused: [], images: null, viewer: null, textures: 0,
                   blob_requests: { started: 0, finished: 0, failed: [] } };
  let context;
  try {
    context = await chromium.launchPersistentContext(profile, {
      executablePath: a.chromium,
      headless: true,
      viewport: { width: 1280, height: 1000 },
      args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
             '--disable-background-networking', '--disable-component-update', '--disable-sync'],
    });
    const page = context.pages()[0] || await context.newPage();
    page.on('console', (m) => { if (m.type() === 'error') result.console_errors.push(m.text()); });
    page.on('pageerror', (e) => result.console_errors.push('uncaught: ' + e.message));
    // No network at view time: anything but the page's own files and in-page blobs is refused.
    await page.route('**/*', (route) => {
      const url = route.request().url();
      if (/^(file|blob|data):/.test(url)) return route.continue();
      result.requests_refused.push(url);
      return route.abort();
    });
    // model-viewer's load / error events, caught on the way down (they do not bubble).
    await page.addInitScript(() => {
      // In-page blobs: the mesh the page hands <model-viewer>, and the textures three.js decodes
      // from it (each image of a GLB is fetched through a blob: URL). Counted here: with request
      // routing on, the browser does not report blob: requests to playwright.
      window.__imrBlobs = { started: 0, finished: 0, failed: [] };
      const fetch0 = window.fetch;
      window.fetch = function (input, init) {
        const url = typeof input === 'string' ? input : (input && input.url) || '';
        if (!url.startsWith('blob:')) return fetch0.call(this, input, init);
        window.__imrBlobs.started += 1;
        return fetch0.call(this, input, init).then((r) => {
          if (r.ok) window.__imrBlobs.finished += 1;
          else window.__imrBlobs.failed.push(url + ': ' + r.status);
          return r;
        }, (e) => { window.__imrBlobs.failed.push(url + ': ' + e); throw e; });
      };
      window.__imrEvents = [];
      for (const type of ['load', 'error'])
        document.addEventListener(type, (e) => {
          if (e.target && e.target.tagName === 'MODEL-VIEWER')
            window.__imrEvents.push(type === 'load' ? 'load' : 'error: ' + JSON.stringify(e.detail || null));
        }, true);
    });
    await page.goto('file://' + path.resolve(a.page));
    await page.waitForFunction(() => window.__imrEvents.length > 0, null, { timeout: a.timeoutMs });
    const events = await page.evaluate(() => window.__imrEvents);
    result.loads = events.filter((e) => e === 'load').length;
    result.errors = events.filter((e) => e !== 'load');
    // The model is drawn once model-viewer says it is visible; give it two frames more.
    await page.waitForFunction(() => {
      const v = document.querySelector('model-viewer');
      return v && v.loaded && v.modelIsVisible;
    }, null, { timeout: a.timeoutMs });
    await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
    result.shown = await page.evaluate(() => window.imrViewer && window.imrViewer.shown);
    result.blob_requests = await page.evaluate(() => window.__imrBlobs);
    // Materials of the shown model whose base colour texture three.js has (a loaded image).
    result.textures = await page.evaluate(() => {
      let n = 0;
      for (const m of document.querySelector('model-viewer').model.materials) {
        const t = m.pbrMetallicRoughness.baseColorTexture;
        if (t && t.texture && t.texture.source) n += 1;
      }
      return n;
    });
    result.images = await page.evaluate(() => {
      const imgs = Array.from(document.images);
      return { total: imgs.length, loaded: imgs.filter((i) => i.complete && i.naturalWidth > 0).length };
    });
    const viewer = page.locator('model-viewer');
    const box = await viewer.boundingBox();
    result.viewer = box && { width: Math.round(box.width), height: Math.round(box.height) };
    await viewer.screenshot({ path: a.viewerScreenshot });
    await page.screenshot({ path: a.screenshot, fullPage: true });
    result.ok = result.loads >= 1 && result.errors.length === 0 && result.console_errors.length === 0 &&
                result.requests_refused.length === 0 && result.images.loaded === result.images.total &&
                result.blob_requests.failed.length === 0;
  } catch (e) {
    result.errors.push(String(e && e.message || e));
  } finally {
    if (context) await context.close().catch(() => {});
    fs.rmSync(profile, { recursive: true, force: true });
  }
  console.log(JSON.stringify(result));
  process.exit(result.ok ? 0 : 1);
})();
