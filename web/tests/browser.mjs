// Drives Debian's headless Chromium (WebGL2 on SwiftShader) with playwright-core
// through a list of page visits, for crates/cli/tests/web.rs (which starts the
// servers and judges the results) and for manual checks:
//
//   node web/tests/browser.mjs PLAN.json > RESULTS.json
//
// PLAN: {"chromium": "/usr/bin/chromium", "visits": [{"name", "url", "expect": "idle" |
// "error", "screenshot": "out.png" (optional, the canvas), "timeout_ms", "viewport":
// [w, h]}]}. RESULTS: [{"name", "outcome": "idle" | "error" | "timeout", "ms" (from
// navigation to the outcome), "error" (the page's message), "notice" (the page's notice
// of a problem that does not stop the view, window.tesseraNotice), "hud" (the text of
// index.html's HUD, or null), "stats" (the
// viewer's last frame statistics), "interaction" (with "drag": [dx, dy] in the visit: the cameras
// before and after a drag and a wheel step, ms to idle again, the address's hash),
// "console" (messages and page errors), "shot" (with "api_shot": PATH: the view's
// screenshot() Blob written there, its type and size; with "download": PATH: the HUD's
// Save PNG button clicked and its download saved there), "touch" (with "touch": true:
// the cameras before and after a one-finger drag, a two-finger pinch and a two-finger
// drag, dispatched as CDP touch events, each waited to idle; the point drawn under the
// pinch's centre before it, in canvas pixels "pinch_at"; a double tap at "tap_at", the
// point drawn there before it "tap_point" and the camera after "tapped"; the canvas's touch-action
// and the page's scroll offset), "pick" (with "pick": {"centre": [x, y], "off": [[x, y],
// ...]} in canvas pixels: pointAt and the full-resolution pick() of the centre ("full"),
// then a double-click there and the
// camera once idle again; then the first "off" pixel with a point under it, a wheel
// step there, the cameras before and after and pointAt of that pixel after), "measure"
// (with "measure": {"size": [w, h], "pixels": [[x, y], ...], "shot": PATH}: index.html's
// Measure button, a click on each canvas pixel, each waited for; the camera, the points
// and distance of window.tesseraMeasure, the HUD's text, a page screenshot)}].
// "cycles" (with "cycles": {"count", "model", "size": [w, h], "gc" (default true: collect
// and measure after every cycle, not only the last), "keep" (the negative control: the
// disposed canvases kept referenced)} on a page that runs nothing
// itself, web/tests/blank.html: `count` times a new canvas, Tessera.view on it, wait for
// its first drawn frame and convergence, the canvas's event listeners counted (CDP
// DOMDebugger.getEventListeners), dispose(), the listeners counted again, the canvas
// removed, the requestAnimationFrame calls counted over 150 ms, garbage collected (CDP
// HeapProfiler.collectGarbage) and the JS heap (Runtime.getHeapUsage), the wasm
// memory and the WebGL contexts made so far that are neither lost nor collected
// counted; per cycle in "per_cycle", and the rAF calls over 1 s after the last),
// "drop" (with "drop": {"control": URL, "shot": PATH}: once the first frame is drawn,
// GET URL/drop (the test's proxy cuts every connection, mid-response, and refuses new
// ones), wait up to 15 s for the page's notice (window.tesseraNotice), its state and a
// canvas screenshot to PATH, then GET URL/restore and wait for idle: "dropped" and
// "restored" states), "three" (with "three": {"model_shot": PATH, "after_shot": PATH
// (optional)} on web/three.html: the three.js camera as a Tessera camera, the pixel of
// the page's cube, the model alone screenshot to model_shot (the screenshot is then
// the whole scene); with "lower_memory": BYTES the model's budget lowered to that and
// the statistics once patches were evicted ("lowered"); the model's dispose() and
// renderer.info.memory before and after), "jumps" (with "jumps": {"latency_ms",
// "cameras": [camera, ...], "dwell_ms"}: once idle, every response made latency_ms late
// (CDP network emulation), the camera set to each in turn for dwell_ms, then waited to
// idle: the stats before the jumps ("before"), ms from the last jump to idle ("ms"),
// the camera then; the screenshot, if any, is taken after), "shared" (with "shared":
// {"model", "size": [w, h], "memory_bytes", "count", "camera"} on web/tests/blank.html:
// `count` views of the model on canvases of that size, each opened with memoryBytes,
// waited until all are idle: their stats ("open"); then all but the last disposed and
// the last waited until it has run a frame and is idle again: its stats ("alone"));
// with "spacer_px", a block that tall between the canvases (the later ones off
// screen), and before the dispose the last scrolled into view and all idle again:
// their stats ("scrolled")),
// "morph" (with "morph": {"shot": PATH, "held_shot": PATH (optional)} on
// web/three.html, with ?clock=hold for held_shot: see the code; "held" and "idle").
// Exit 0 when every visit ran (whatever its outcome), 2 on a driver failure.

import { readFileSync, writeFileSync } from 'node:fs';
import { launchChromium } from './chromium.mjs';

const plan = JSON.parse(readFileSync(process.argv[2], 'utf8'));
const browser = await launchChromium(plan, [], 'browser.mjs');

const results = [];
for (const visit of plan.visits) {
  const [w, h] = visit.viewport || [800, 600];
  const context = await browser.newContext({
    viewport: { width: w, height: h },
    deviceScaleFactor: 1,
    acceptDownloads: true,
    hasTouch: !!visit.touch,
  });
  if (visit.cycles) {
    // Before any page script: count the WebGL contexts made (weakly held, so a context
    // the page lets go of can be collected) and the requestAnimationFrame calls.
    await context.addInitScript(() => {
      const seen = new WeakSet();
      window.__glContexts = [];
      const getContext = HTMLCanvasElement.prototype.getContext;
      HTMLCanvasElement.prototype.getContext = function (type, ...rest) {
        const ctx = getContext.call(this, type, ...rest);
        if (ctx && /^(webgl|webgl2|experimental-webgl)$/.test(type) && !seen.has(ctx)) {
          seen.add(ctx);
          window.__glContexts.push(new WeakRef(ctx));
        }
        return ctx;
      };
      window.__rafCalls = 0;
      const raf = window.requestAnimationFrame.bind(window);
      window.requestAnimationFrame = (cb) => {
        window.__rafCalls++;
        return raf(cb);
      };
    });
  }
  const page = await context.newPage();
  const consoleLines = [];
  page.on('console', (m) => consoleLines.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => consoleLines.push(`pageerror: ${e.message}`));
  const t0 = Date.now();
  let outcome = 'timeout';
  let morph = null;
  try {
    await page.goto(visit.url, { waitUntil: 'load', timeout: visit.timeout_ms || 60000 });
    // "morph" with "held_shot" (web/three.html?clock=hold): once the patches stop
    // coming with the clock held (nothing pending, a cut past the roots, the same for
    // 1 s), the model alone to held_shot and the stats ("held"); then the clock let go.
    if (visit.morph && visit.morph.held_shot) {
      const quiet = async () => {
        const h = await page.waitForFunction(
          () => {
            const s = window.tesseraError ? null : window.tesseraStats;
            return s && s.pending === 0 && s.triangles > s.first_triangles ? JSON.stringify([s.triangles, s.nodes, s.requests, s.bytes_received]) : false;
          },
          null,
          { timeout: visit.timeout_ms || 60000, polling: 50 },
        );
        return h.jsonValue();
      };
      let key = await quiet();
      for (let k = 0; k < 30; k++) {
        await page.waitForTimeout(1000);
        const next = await quiet();
        if (next === key) break;
        key = next;
      }
      await page.evaluate(() => window.tesseraThree.modelOnly(true));
      await page.locator('#view').screenshot({ path: visit.morph.held_shot });
      morph = { held: await page.evaluate(() => window.tesseraStats) };
      await page.evaluate(() => {
        window.tesseraThree.modelOnly(false);
        window.tesseraThree.release();
      });
    }
    // A page of cycles runs nothing until the driver does; one to drop the connection
    // of waits only for the first frame drawn.
    const handle = visit.cycles || visit.shared
      ? null
      : await page.waitForFunction(
          visit.drop
            ? () => (window.tesseraError ? 'error' : window.tesseraStats && window.tesseraStats.triangles > 0 ? 'drawn' : false)
            : () => (window.tesseraError ? 'error' : window.tesseraIdle === true ? 'idle' : false),
          null,
          { timeout: visit.timeout_ms || 60000, polling: visit.drop ? 10 : 50 },
        );
    outcome = handle ? await handle.jsonValue() : 'loaded';
  } catch (e) {
    consoleLines.push(`driver: ${e.message.split('\n')[0]}`);
  }
  const ms = Date.now() - t0;
  // Optional: a mouse drag and a wheel step over the canvas once idle, then wait for
  // idle again; the cameras before and after, and the address, are reported.
  let interaction = null;
  if (visit.drag && outcome === 'idle') {
    try {
      const before = await page.evaluate(() => window.tesseraView.camera());
      const box = await page.locator('#view').boundingBox();
      const [cx, cy] = [box.x + box.width / 2, box.y + box.height / 2];
      await page.mouse.move(cx, cy);
      await page.mouse.down();
      for (let i = 1; i <= 10; i++) await page.mouse.move(cx + (visit.drag[0] * i) / 10, cy + (visit.drag[1] * i) / 10);
      await page.mouse.up();
      await page.mouse.wheel(0, -100);
      await page.waitForFunction(() => window.tesseraIdle === false, null, { timeout: 5000, polling: 10 }).catch(() => {});
      const t1 = Date.now();
      await page.waitForFunction(() => window.tesseraIdle === true, null, { timeout: visit.timeout_ms || 60000, polling: 50 });
      const after = await page.evaluate(() => window.tesseraView.camera());
      interaction = { before, after, ms: Date.now() - t1, hash: await page.evaluate(() => location.hash) };
    } catch (e) {
      consoleLines.push(`driver: interaction: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: open / dispose cycles on one page (see the top of this file).
  let cycles = null;
  if (visit.cycles && outcome !== 'timeout') {
    try {
      const cdp = await context.newCDPSession(page);
      // Collected twice, then counted; while a WebGL context is still live (work the
      // disposed view started may hold it for a moment: a fetch or a decode job being
      // answered), collected and counted again, for up to 3 s. A context that is really
      // leaked stays (the "keep" control).
      const heap = async (released = true) => {
        let more;
        for (let attempt = 0; ; attempt++) {
          await cdp.send('HeapProfiler.collectGarbage');
          await cdp.send('HeapProfiler.collectGarbage');
          more = await countContexts();
          more.gc_rounds = attempt + 1;
          if (!released || more.contexts_live === 0 || attempt >= 15 || visit.cycles.keep) break;
          await new Promise((r) => setTimeout(r, 200));
        }
        const h = await cdp.send('Runtime.getHeapUsage');
        return { js_heap_used: h.usedSize, js_heap_total: h.totalSize, ...more };
      };
      const countContexts = async () => {
        return page.evaluate(async () => {
          const wasm = await (await import('./tessera_web.js')).default();
          const refs = window.__glContexts;
          const alive = refs.map((r) => r.deref()).filter((c) => c);
          return {
            wasm_bytes: wasm.memory.buffer.byteLength,
            contexts_made: refs.length,
            contexts_unreleased: alive.length,
            contexts_live: alive.filter((c) => !c.isContextLost()).length,
          };
        });
      };
      const listeners = async () => {
        const { result } = await cdp.send('Runtime.evaluate', { expression: 'window.__cycleCanvas' });
        const { listeners } = await cdp.send('DOMDebugger.getEventListeners', { objectId: result.objectId });
        await cdp.send('Runtime.releaseObject', { objectId: result.objectId });
        return listeners.map((l) => l.type);
      };
      const { count, model, size } = visit.cycles;
      const per_cycle = [];
      const before = await heap();
      for (let k = 0; k < count; k++) {
        const t = Date.now();
        const opened = await page.evaluate(
          async ({ model, size }) => {
            const { Tessera } = await import('./tessera.js');
            const c = document.createElement('canvas');
            [c.width, c.height] = size;
            document.body.appendChild(c);
            window.__cycleCanvas = c;
            const v = await Tessera.view(c, { url: model, autoResize: false });
            window.__cycleView = v;
            const s = await new Promise((resolve, reject) => {
              const timer = setTimeout(() => reject(new Error('no convergence in 60 s')), 60000);
              if (v.idle) resolve(v.stats);
              v.addEventListener('idle', (e) => { clearTimeout(timer); resolve(e.detail); }, { once: true });
              v.addEventListener('error', (e) => { clearTimeout(timer); reject(new Error(e.detail.message)); }, { once: true });
            });
            return { triangles: s.triangles, frame: s.frame };
          },
          { model, size },
        );
        const on = await listeners();
        // The heap with the view open (collected), against the same after dispose().
        const open = visit.cycles.gc === false ? {} : await heap(false);
        const rafBefore = await page.evaluate(async () => {
          window.__cycleView.dispose();
          window.__cycleView = null;
          const n = window.__rafCalls;
          await new Promise((r) => setTimeout(r, 150));
          return [n, window.__rafCalls];
        });
        const off = await listeners();
        await page.evaluate((keep) => {
          window.__cycleCanvas.remove();
          // The negative control ("keep": true) holds on to the canvases, so their
          // contexts cannot be collected: the count must see them.
          if (keep) (window.__kept = window.__kept || []).push(window.__cycleCanvas);
          window.__cycleCanvas = null;
        }, !!visit.cycles.keep);
        per_cycle.push({
          ...opened,
          ms: Date.now() - t,
          listeners_before: on,
          listeners_after: off,
          raf_after_dispose: rafBefore[1] - rafBefore[0],
          open_js_heap_used: open.js_heap_used,
          open_wasm_bytes: open.wasm_bytes,
          open_contexts_live: open.contexts_live,
          ...(visit.cycles.gc === false && k + 1 < count ? {} : await heap()),
        });
      }
      const r0 = await page.evaluate(() => window.__rafCalls);
      await page.waitForTimeout(1000);
      const r1 = await page.evaluate(() => window.__rafCalls);
      cycles = { before, per_cycle, raf_last_second: r1 - r0 };
    } catch (e) {
      consoleLines.push(`driver: cycles: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: views sharing the page's memory (see the top of this file).
  let shared = null;
  if (visit.shared && outcome !== 'timeout') {
    try {
      shared = await page.evaluate(async ({ model, size, memory_bytes, count, camera, spacer_px = 0 }) => {
        const { Tessera } = await import('./tessera.js');
        const settle = (v) =>
          new Promise((resolve, reject) => {
            const timer = setTimeout(() => reject(new Error(`no convergence in 60 s: ${JSON.stringify(v.stats)}`)), 60000);
            const check = () => {
              if (v.idle) {
                clearTimeout(timer);
                resolve(v.stats);
              } else setTimeout(check, 50);
            };
            check();
          });
        const views = [];
        const canvases = [];
        for (let k = 0; k < count; k++) {
          if (k > 0 && spacer_px > 0) {
            const gap = document.createElement('div');
            gap.style.height = `${spacer_px}px`;
            document.body.appendChild(gap);
          }
          const c = document.createElement('canvas');
          [c.width, c.height] = size;
          c.style.display = 'block';
          document.body.appendChild(c);
          canvases.push(c);
          views.push(await Tessera.view(c, { url: model, autoResize: false, memoryBytes: memory_bytes, camera }));
        }
        // Idle together: each once more after the others (a share may move as they load).
        const settleAll = async () => {
          for (let round = 0; round < 2; round++) for (const v of views) await settle(v);
        };
        await settleAll();
        const open = views.map((v) => v.stats);
        // Spaced: the last canvas scrolled into view (the others off screen), then idle.
        let scrolled = null;
        if (spacer_px > 0) {
          canvases[canvases.length - 1].scrollIntoView();
          const t = Date.now();
          const turned = () => views.every((v, k) => v.stats && v.stats.hidden === (k < views.length - 1));
          while (!turned() && Date.now() - t < 5000) await new Promise((r) => setTimeout(r, 20));
          // The budgets follow the demands within about 2 s (a falling demand halves
          // every 0.25 s, BudgetSplit): idle with the same budgets for 1 s.
          let last = null;
          for (let k = 0; k < 30; k++) {
            await settleAll();
            const now = JSON.stringify(views.map((v) => [v.stats.gpu_budget_bytes, v.stats.triangles]));
            if (now === last) break;
            last = now;
            await new Promise((r) => setTimeout(r, 1000));
          }
          scrolled = views.map((v) => v.stats);
        }
        const last = views[views.length - 1];
        const frame = last.stats.frame;
        for (const v of views.slice(0, -1)) v.dispose();
        const t = Date.now();
        while (last.stats.frame === frame && Date.now() - t < 5000) await new Promise((r) => setTimeout(r, 20));
        const alone = await settle(last);
        last.dispose();
        return { open, scrolled, alone };
      }, visit.shared);
    } catch (e) {
      consoleLines.push(`driver: shared: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: the connection dropped mid-stream after the first frame, then back.
  let drop = null;
  if (visit.drop && outcome !== 'timeout') {
    try {
      const snapshot = () =>
        page.evaluate(() => ({
          notice: window.tesseraNotice || null,
          idle: window.tesseraIdle,
          error: window.tesseraError,
          stats: window.tesseraStats || null,
        }));
      drop = {};
      drop.first = await snapshot();
      const r = await fetch(`${visit.drop.control}/drop`);
      if (!r.ok) throw new Error(`proxy control: HTTP ${r.status}`);
      const t1 = Date.now();
      await page
        .waitForFunction(() => !!window.tesseraNotice || !!window.tesseraError, null, { timeout: 15000, polling: 50 })
        .catch(() => {});
      drop.dropped = { ...(await snapshot()), ms: Date.now() - t1 };
      if (visit.drop.shot) await page.locator('#view').screenshot({ path: visit.drop.shot });
      await fetch(`${visit.drop.control}/restore`);
      const t2 = Date.now();
      await page
        .waitForFunction(() => window.tesseraIdle === true && !window.tesseraNotice, null, { timeout: visit.timeout_ms || 60000, polling: 50 })
        .catch(() => {});
      drop.restored = { ...(await snapshot()), ms: Date.now() - t2 };
      if (visit.screenshot && drop.restored.idle) await page.locator('#view').screenshot({ path: visit.screenshot });
    } catch (e) {
      consoleLines.push(`driver: drop: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: once idle, a slow network (CDP Network.emulateNetworkConditions: every
  // response "latency_ms" late) and the camera jumped through "cameras" (setCamera,
  // "dwell_ms" on each), then waited to idle: the stats when the jumps began
  // ("before") and "ms" from the last jump to idle.
  let jumps = null;
  if (visit.jumps && outcome === 'idle') {
    try {
      const cdp = await context.newCDPSession(page);
      await cdp.send('Network.enable');
      await cdp.send('Network.emulateNetworkConditions', {
        offline: false,
        latency: visit.jumps.latency_ms,
        downloadThroughput: -1,
        uploadThroughput: -1,
      });
      jumps = { before: await page.evaluate(() => window.tesseraStats) };
      for (const c of visit.jumps.cameras) {
        await page.evaluate((c) => {
          window.tesseraIdle = false;
          window.tesseraView.setCamera(c);
        }, c);
        await page.waitForTimeout(visit.jumps.dwell_ms);
      }
      const t1 = Date.now();
      await page.waitForFunction(() => window.tesseraIdle === true, null, { timeout: visit.timeout_ms || 60000, polling: 50 });
      jumps.ms = Date.now() - t1;
      jumps.camera = await page.evaluate(() => window.tesseraView.camera());
    } catch (e) {
      consoleLines.push(`driver: jumps: ${e.message.split('\n')[0]}`);
    }
  }
  const state = await page
    .evaluate(() => ({
      error: window.tesseraError,
      errorShown: (() => {
        const e = document.getElementById('error');
        return e && getComputedStyle(e).display !== 'none' ? e.innerText : null;
      })(),
      stats: window.tesseraStats || null,
      notice: window.tesseraNotice || null,
      // The page's HUD text (index.html), or null.
      hud: (() => {
        const e = document.getElementById('hud-text');
        return e ? e.textContent : null;
      })(),
    }))
    .catch(() => ({}));
  // Optional: touch gestures (CDP Input.dispatchTouchEvent: Chromium turns them into
  // pointer events of pointerType 'touch'), each waited to idle.
  let touch = null;
  if (visit.touch && outcome === 'idle') {
    try {
      const cdp = await context.newCDPSession(page);
      const box = await page.locator('#view').boundingBox();
      const [cx, cy] = [box.x + box.width / 2, box.y + box.height / 2];
      const camera = () => page.evaluate(() => window.tesseraView.camera());
      const settle = async () => {
        await page.waitForFunction(() => window.tesseraIdle === false, null, { timeout: 5000, polling: 10 }).catch(() => {});
        await page.waitForFunction(() => window.tesseraIdle === true, null, { timeout: visit.timeout_ms || 60000, polling: 50 });
      };
      // Fingers from `from` to `to` ([[x, y], ...] relative to the centre) in 10 moves.
      const gesture = async (from, to) => {
        const at = (k) => from.map(([x, y], i) => ({
          x: cx + x + ((to[i][0] - x) * k) / 10,
          y: cy + y + ((to[i][1] - y) * k) / 10,
          id: i,
        }));
        await cdp.send('Input.dispatchTouchEvent', { type: 'touchStart', touchPoints: at(0) });
        for (let k = 1; k <= 10; k++) {
          await cdp.send('Input.dispatchTouchEvent', { type: 'touchMove', touchPoints: at(k) });
        }
        await cdp.send('Input.dispatchTouchEvent', { type: 'touchEnd', touchPoints: [] });
        await settle();
        return camera();
      };
      const start = await camera();
      const orbit = await gesture([[0, 0]], [[150, 0]]);
      // The pinch about a point off the centre (-60, +30): the point drawn there first.
      const pinch_at = [box.width / 2 - 60, box.height / 2 + 30];
      const pinch_point = await page.evaluate(([x, y]) => window.tesseraView.pointAt(x, y), pinch_at);
      const pinch = await gesture([[-100, 30], [-20, 30]], [[-180, 30], [60, 30]]);
      const pan = await gesture([[-50, 0], [50, 0]], [[30, 40], [130, 40]]);
      // A double tap off the centre (+40, -20): the point drawn there first, then two
      // quick taps, then the camera once idle (recentred on it).
      const tap_at = [box.width / 2 + 40, box.height / 2 - 20];
      const tap_point = await page.evaluate(([x, y]) => window.tesseraView.pointAt(x, y), tap_at);
      for (let i = 0; i < 2; i++) {
        await cdp.send('Input.dispatchTouchEvent', { type: 'touchStart', touchPoints: [{ x: box.x + tap_at[0], y: box.y + tap_at[1], id: 0 }] });
        await cdp.send('Input.dispatchTouchEvent', { type: 'touchEnd', touchPoints: [] });
      }
      await settle();
      const tapped = await camera();
      const page_state = await page.evaluate(() => ({
        touchAction: getComputedStyle(document.getElementById('view')).touchAction,
        scroll: [window.scrollX, window.scrollY],
      }));
      touch = { start, orbit, pinch, pan, pinch_at, pinch_point, tap_at, tap_point, tapped, ...page_state };
    } catch (e) {
      consoleLines.push(`driver: touch: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: picking through the depth buffer: double-click recentre and zoom to the
  // cursor.
  let pick = null;
  if (visit.pick && outcome === 'idle') {
    try {
      const box = await page.locator('#view').boundingBox();
      const camera = () => page.evaluate(() => window.tesseraView.camera());
      const pointAt = ([x, y]) => page.evaluate(([x, y]) => window.tesseraView.pointAt(x, y), [x, y]);
      const settle = async () => {
        await page.waitForFunction(() => window.tesseraIdle === false, null, { timeout: 5000, polling: 10 }).catch(() => {});
        await page.waitForFunction(() => window.tesseraIdle === true, null, { timeout: visit.timeout_ms || 60000, polling: 50 });
      };
      // Canvas pixel (x, y) -> page coordinates of its centre (the canvas is shown at
      // its pixel size here).
      const client = ([x, y]) => [box.x + ((x + 0.5) * box.width) / visit.pick.size[0], box.y + ((y + 0.5) * box.height) / visit.pick.size[1]];
      const c = visit.pick.centre;
      const before = await camera();
      const centre_point = await pointAt(c);
      // The full-resolution pick of the same pixel (leaf patches fetched for it).
      const full = await page.evaluate(([x, y]) => window.tesseraView.pick(x, y), c);
      await page.mouse.dblclick(...client(c));
      await settle();
      const recentred = await camera();
      let off = null;
      for (const px of visit.pick.off) {
        const p = await pointAt(px);
        if (p) {
          off = { pixel: px, point: p };
          break;
        }
      }
      let zoom = null;
      if (off) {
        await page.mouse.move(...client(off.pixel));
        await page.mouse.wheel(0, -100);
        await settle();
        zoom = { ...off, after: await camera(), point_after: await pointAt(off.pixel) };
      }
      pick = { before, centre_point, full, recentred, zoom };
    } catch (e) {
      consoleLines.push(`driver: pick: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: the page's Measure tool (index.html): the button, then a click on each
  // of the canvas pixels given; the camera, the measured points and distance, and a
  // screenshot of the page (the overlay with them) to "measure_shot".
  let measure = null;
  if (visit.measure && outcome === 'idle') {
    try {
      const box = await page.locator('#view').boundingBox();
      const size = visit.measure.size;
      const client = ([x, y]) => [box.x + ((x + 0.5) * box.width) / size[0], box.y + ((y + 0.5) * box.height) / size[1]];
      await page.click('#measure');
      const camera = await page.evaluate(() => window.tesseraView.camera());
      for (const [i, px] of visit.measure.pixels.entries()) {
        await page.mouse.click(...client(px));
        await page.waitForFunction((n) => window.tesseraMeasure && window.tesseraMeasure.points.length === n, i + 1, { timeout: 30000, polling: 50 });
      }
      const result = await page.evaluate(() => window.tesseraMeasure);
      const text = await page.evaluate(() => document.getElementById('measure-text').textContent);
      if (visit.measure.shot) await page.screenshot({ path: visit.measure.shot });
      measure = { camera, ...result, text, camera_after: await page.evaluate(() => window.tesseraView.camera()) };
    } catch (e) {
      consoleLines.push(`driver: measure: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: the module's screenshot() and the page's Save PNG button, once idle.
  let shot = null;
  if ((visit.api_shot || visit.download) && outcome === 'idle') {
    try {
      shot = {};
      if (visit.api_shot) {
        const r = await page.evaluate(async () => {
          const blob = await window.tesseraView.screenshot();
          const bytes = new Uint8Array(await blob.arrayBuffer());
          let bin = '';
          for (let i = 0; i < bytes.length; i += 0x8000) bin += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
          const c = document.getElementById('view');
          return { type: blob.type, size: blob.size, base64: btoa(bin), canvas: [c.width, c.height] };
        });
        writeFileSync(visit.api_shot, Buffer.from(r.base64, 'base64'));
        if (visit.naive_shot) {
          // For comparison: the canvas read in a later task than its frame (what
          // screenshot() avoids): a WebGL canvas is cleared once composited.
          const naive = await page.evaluate(async () => {
            await new Promise((r) => setTimeout(r, 200));
            const blob = await new Promise((r) => document.getElementById('view').toBlob(r, 'image/png'));
            const bytes = new Uint8Array(await blob.arrayBuffer());
            let bin = '';
            for (let i = 0; i < bytes.length; i += 0x8000) bin += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
            return btoa(bin);
          });
          writeFileSync(visit.naive_shot, Buffer.from(naive, 'base64'));
        }
        shot.type = r.type;
        shot.size = r.size;
        shot.canvas = r.canvas;
      }
      if (visit.download) {
        const [download] = await Promise.all([page.waitForEvent('download', { timeout: 30000 }), page.click('#save-png')]);
        await download.saveAs(visit.download);
        shot.download_name = download.suggestedFilename();
      }
    } catch (e) {
      consoleLines.push(`driver: shot: ${e.message.split('\n')[0]}`);
    }
  }
  // Optional: web/three.html (the three.js adapter), once idle: the camera it drew
  // (window.tesseraThree.camera(), model coordinates), the page's cube's pixel, the
  // model alone over the background (the page's objects hidden, two frames drawn) as
  // a screenshot to "model_shot", then the model's dispose() with renderer.info's
  // counts before and after.
  let three = null;
  if (visit.three && outcome === 'idle') {
    try {
      three = await page.evaluate(() => ({ camera: window.tesseraThree.camera(), cube: window.tesseraThree.cubePixel() }));
      if (visit.screenshot) await page.locator('#view').screenshot({ path: visit.screenshot });
      await page.evaluate(() => window.tesseraThree.modelOnly(true));
      await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
      await page.locator('#view').screenshot({ path: visit.three.model_shot });
      await page.evaluate(() => window.tesseraThree.modelOnly(false));
      if (visit.three.lower_memory) {
        // A lower budget: patches evicted, their meshes disposed.
        await page.evaluate((b) => window.tesseraThree.model.setMemoryBytes(b), visit.three.lower_memory);
        await page.waitForFunction(
          () => {
            const s = window.tesseraStats;
            return s.evicted > 0 && s.resident_bytes <= s.budget_bytes && s.meshes === s.resident_nodes;
          },
          null,
          { timeout: 30000, polling: 50 },
        );
        three.lowered = await page.evaluate(() => window.tesseraStats);
      }
      three.dispose = await page.evaluate(() => window.tesseraThree.dispose());
      await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
      if (visit.three.after_shot) await page.locator('#view').screenshot({ path: visit.three.after_shot });
      three.after_frames = await page.evaluate(() => ({ ...window.tesseraThree.renderer.info.memory }));
    } catch (e) {
      consoleLines.push(`driver: three: ${e.message.split('\n')[0]}`);
    }
  }
  // "morph" (web/three.html) once idle: the model alone to "shot", the stats ("idle").
  if (visit.morph && outcome === 'idle') {
    try {
      await page.evaluate(() => window.tesseraThree.modelOnly(true));
      await page.locator('#view').screenshot({ path: visit.morph.shot });
      morph = { ...morph, idle: await page.evaluate(() => window.tesseraStats) };
    } catch (e) {
      consoleLines.push(`driver: morph: ${e.message.split('\n')[0]}`);
    }
  }
  if (visit.screenshot && outcome === visit.expect && !visit.drop && !visit.three) {
    await page.locator('#view').screenshot({ path: visit.screenshot });
  }
  results.push({ name: visit.name, outcome, ms, ...state, interaction, shot, touch, pick, measure, cycles, drop, three, jumps, shared, morph, console: consoleLines });
  await context.close();
}
await browser.close();
process.stdout.write(JSON.stringify(results, null, 1) + '\n');
