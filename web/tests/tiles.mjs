// Drives headless Chromium (WebGL2 on SwiftShader) through web/tests/tiles.html for
// crates/cli/tests/tiles_clients.rs (issue 33), which serves the page and the tileset
// and judges the pictures:
//
//   node web/tests/tiles.mjs PLAN.json > RESULTS.json
//
// PLAN: {"chromium", "extra_args", "visits": [{"name", "url", "shot" (PNG of the
// canvas), "viewport": [w, h], "timeout_ms"}]}. RESULTS: [{"name", "outcome": "idle" |
// "error" | "timeout", "ms" (navigation to idle), "result" (the page's
// window.tilesResult: tiles and bytes fetched, the client's statistics), "error",
// "console"}]. Exit 0 when every visit ran, 2 when Chromium could not start.

import { readFileSync } from 'node:fs';
import { launchChromium } from './chromium.mjs';

const plan = JSON.parse(readFileSync(process.argv[2], 'utf8'));
const browser = await launchChromium(plan, ['--ignore-gpu-blocklist'], 'tiles.mjs');
const results = [];
for (const visit of plan.visits) {
  const [w, h] = visit.viewport || [480, 360];
  const context = await browser.newContext({ viewport: { width: w, height: h }, deviceScaleFactor: 1 });
  const page = await context.newPage();
  const consoleLines = [];
  page.on('console', (m) => consoleLines.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => consoleLines.push(`pageerror: ${e.message}`));
  const t0 = Date.now();
  const out = { name: visit.name, outcome: 'timeout' };
  try {
    await page.goto(visit.url, { waitUntil: 'load', timeout: visit.timeout_ms || 60000 });
    const h = await page.waitForFunction(
      () => (window.tilesError ? { error: window.tilesError } : window.tilesResult ? { result: window.tilesResult } : false),
      null,
      { timeout: visit.timeout_ms || 60000, polling: 100 },
    );
    const v = await h.jsonValue();
    out.ms = Date.now() - t0;
    if (v.error) {
      out.outcome = 'error';
      out.error = v.error;
    } else {
      out.outcome = 'idle';
      out.result = v.result;
      if (visit.shot) await page.locator('#canvas').screenshot({ path: visit.shot });
    }
  } catch (e) {
    out.error = String(e.message || e);
  }
  out.console = consoleLines.slice(-40);
  results.push(out);
  await context.close();
}
await browser.close();
process.stdout.write(JSON.stringify(results));
