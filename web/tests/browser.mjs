// Drives Debian's headless Chromium (WebGL2 on SwiftShader) with playwright-core
// through a list of page visits, for crates/cli/tests/web.rs (which starts the
// servers and judges the results) and for manual checks:
//
//   node web/tests/browser.mjs PLAN.json > RESULTS.json
//
// PLAN: {"chromium": "/usr/bin/chromium", "visits": [{"name", "url", "expect": "idle" |
// "error", "screenshot": "out.png" (optional, the canvas), "timeout_ms", "viewport":
// [w, h]}]}. RESULTS: [{"name", "outcome": "idle" | "error" | "timeout", "ms" (from
// navigation to the outcome), "error" (the page's message), "stats" (the viewer's last
// frame statistics), "interaction" (with "drag": [dx, dy] in the visit: the cameras
// before and after a drag and a wheel step, ms to idle again, the address's hash),
// "console" (messages and page errors), "shot" (with "api_shot": PATH: the view's
// screenshot() Blob written there, its type and size; with "download": PATH: the HUD's
// Save PNG button clicked and its download saved there), "touch" (with "touch": true:
// the cameras before and after a one-finger drag, a two-finger pinch and a two-finger
// drag, dispatched as CDP touch events, each waited to idle; the point drawn under the
// pinch's centre before it, in canvas pixels "pinch_at"; the canvas's touch-action
// and the page's scroll offset), "pick" (with "pick": {"centre": [x, y], "off": [[x, y],
// ...]} in canvas pixels: pointAt of the centre, then a double-click there and the
// camera once idle again; then the first "off" pixel with a point under it, a wheel
// step there, the cameras before and after and pointAt of that pixel after)}].
// Exit 0 when every visit ran (whatever its outcome), 2 on a driver failure.

import { readFileSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);

function loadPlaywright() {
  try {
    return require('playwright-core');
  } catch (_) {
    // Installed by .ci/run with `npm install` in web/, or globally.
    for (const p of [join(process.cwd(), 'node_modules', 'playwright-core'), '/usr/lib/node_modules/playwright-core', '/usr/local/lib/node_modules/playwright-core']) {
      try {
        return require(p);
      } catch (_) {}
    }
    throw new Error('playwright-core is missing: run `npm install` in web/ (or npm install -g playwright-core)');
  }
}

const plan = JSON.parse(readFileSync(process.argv[2], 'utf8'));
const { chromium } = loadPlaywright();
let browser;
try {
  browser = await chromium.launch({
    executablePath: plan.chromium || '/usr/bin/chromium',
    headless: true,
    // ../shared/STACK.md: headless Chromium with WebGL2 on SwiftShader (playwright
    // gives each launch a fresh profile directory of its own).
    args: [
      '--no-sandbox',
      '--disable-quic',
      '--no-first-run',
      '--disable-background-networking',
      '--disable-component-update',
      '--disable-sync',
      '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader',
      ...(plan.extra_args || []),
    ],
  });
} catch (e) {
  console.error(`browser.mjs: cannot start Chromium: ${e.message}`);
  process.exit(2);
}

const results = [];
for (const visit of plan.visits) {
  const [w, h] = visit.viewport || [800, 600];
  const context = await browser.newContext({
    viewport: { width: w, height: h },
    deviceScaleFactor: 1,
    acceptDownloads: true,
    hasTouch: !!visit.touch,
  });
  const page = await context.newPage();
  const consoleLines = [];
  page.on('console', (m) => consoleLines.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => consoleLines.push(`pageerror: ${e.message}`));
  const t0 = Date.now();
  let outcome = 'timeout';
  try {
    await page.goto(visit.url, { waitUntil: 'load', timeout: visit.timeout_ms || 60000 });
    const handle = await page.waitForFunction(
      () => (window.tesseraError ? 'error' : window.tesseraIdle === true ? 'idle' : false),
      null,
      { timeout: visit.timeout_ms || 60000, polling: 50 },
    );
    outcome = await handle.jsonValue();
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
  const state = await page
    .evaluate(() => ({
      error: window.tesseraError,
      errorShown: (() => {
        const e = document.getElementById('error');
        return e && getComputedStyle(e).display !== 'none' ? e.innerText : null;
      })(),
      stats: window.tesseraStats || null,
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
      const page_state = await page.evaluate(() => ({
        touchAction: getComputedStyle(document.getElementById('view')).touchAction,
        scroll: [window.scrollX, window.scrollY],
      }));
      touch = { start, orbit, pinch, pan, pinch_at, pinch_point, ...page_state };
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
      pick = { before, centre_point, recentred, zoom };
    } catch (e) {
      consoleLines.push(`driver: pick: ${e.message.split('\n')[0]}`);
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
  if (visit.screenshot && outcome === visit.expect) {
    await page.locator('#view').screenshot({ path: visit.screenshot });
  }
  results.push({ name: visit.name, outcome, ms, ...state, interaction, shot, touch, pick, console: consoleLines });
  await context.close();
}
await browser.close();
process.stdout.write(JSON.stringify(results, null, 1) + '\n');
