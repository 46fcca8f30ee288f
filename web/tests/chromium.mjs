// Headless Chromium for the browser test (browser.mjs) and the browser benchmark
// (bench-web.mjs): playwright-core found where `npm install` in web/ (as .ci/run does)
// or a global install puts it, and Debian's Chromium launched with WebGL2 on SwiftShader
// (../shared/STACK.md; playwright gives each launch a fresh profile directory).

import { join } from 'node:path';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);

function loadPlaywright() {
  const here = new URL('..', import.meta.url).pathname; // web/
  for (const p of ['playwright-core', join(here, 'node_modules', 'playwright-core'), join(process.cwd(), 'node_modules', 'playwright-core'), '/usr/lib/node_modules/playwright-core', '/usr/local/lib/node_modules/playwright-core']) {
    try {
      return require(p);
    } catch (_) {}
  }
  throw new Error('playwright-core is missing: run `npm install` in web/ (or npm install -g playwright-core)');
}

// The browser of `plan.chromium` (default /usr/bin/chromium) with `args` and the plan's
// `extra_args` beside the usual flags; `who` names the driver in the message it exits
// with (status 2) when Chromium cannot start.
export async function launchChromium(plan, args, who) {
  try {
    const { chromium } = loadPlaywright();
    return await chromium.launch({
      executablePath: plan.chromium || '/usr/bin/chromium',
      headless: true,
      args: [
        '--no-sandbox',
        '--disable-quic',
        '--no-first-run',
        '--disable-background-networking',
        '--disable-component-update',
        '--disable-sync',
        '--use-angle=swiftshader',
        '--enable-unsafe-swiftshader',
        ...args,
        ...(plan.extra_args || []),
      ],
    });
  } catch (e) {
    console.error(`${who}: cannot start Chromium: ${e.message}`);
    process.exit(2);
  }
}
