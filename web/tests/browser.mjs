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
// "console" (messages and page errors)}].
// Exit 0 when every visit ran (whatever its outcome), 2 on a driver failure.

import { readFileSync } from 'node:fs';
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
  const context = await browser.newContext({ viewport: { width: w, height: h }, deviceScaleFactor: 1 });
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
  if (visit.screenshot && outcome === visit.expect) {
    await page.locator('#view').screenshot({ path: visit.screenshot });
  }
  results.push({ name: visit.name, outcome, ms, ...state, interaction, console: consoleLines });
  await context.close();
}
await browser.close();
process.stdout.write(JSON.stringify(results, null, 1) + '\n');
