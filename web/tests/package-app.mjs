// The browser module tried as a web developer installs it: web/dist packed (npm pack),
// the tarball unpacked as node_modules/tessera-web of a fresh TypeScript app (with
// three, @types/three, typescript and vite from web/node_modules), type-checked with
// tsc against the package's declarations, bundled with `vite build` (the .wasm and the
// decode worker found through import.meta.url), served by a static server and opened
// in Chromium on a model until the view converges. For crates/cli/tests/web.rs:
//
//   node web/tests/package-app.mjs MODEL_URL OUT_DIR > RESULT.json
//
// RESULT: {"tsc": "ok" | error text, "files": [bundle files], "outcome": "idle" |
// "error" | "timeout", "ms", "stats" (the view's idle stats), "error", "console"}.

import { execFileSync } from 'node:child_process';
import { mkdirSync, readdirSync, readFileSync, symlinkSync, writeFileSync, existsSync } from 'node:fs';
import { createServer } from 'node:http';
import { extname, join } from 'node:path';
import { launchChromium } from './chromium.mjs';

const [modelUrl, out] = process.argv.slice(2);
if (!modelUrl || !out) {
  console.error('usage: node web/tests/package-app.mjs MODEL_URL OUT_DIR');
  process.exit(2);
}
const web = new URL('..', import.meta.url).pathname;
const mods = join(web, 'node_modules');
const result = { tsc: null, files: [], outcome: null, ms: null, stats: null, error: null, console: [] };

// The package, as npm would install it.
mkdirSync(join(out, 'node_modules', '@types'), { recursive: true });
const tgz = execFileSync('npm', ['pack', join(web, 'dist'), '--pack-destination', out, '--silent'], { encoding: 'utf8' }).trim().split('\n').pop();
mkdirSync(join(out, 'pkg'), { recursive: true });
execFileSync('tar', ['xzf', join(out, tgz), '-C', join(out, 'pkg')]);
symlinkSync(join(out, 'pkg', 'package'), join(out, 'node_modules', 'tessera-web'));
for (const dep of ['three', 'typescript', 'vite']) symlinkSync(join(mods, dep), join(out, 'node_modules', dep));
symlinkSync(join(mods, '@types', 'three'), join(out, 'node_modules', '@types', 'three'));

// The app: a canvas view, and the three.js adapter's types used as a user would.
mkdirSync(join(out, 'src'), { recursive: true });
writeFileSync(join(out, 'package.json'), JSON.stringify({ name: 'app', private: true, type: 'module' }));
writeFileSync(join(out, 'tsconfig.json'), JSON.stringify({
  compilerOptions: { target: 'es2022', module: 'esnext', moduleResolution: 'bundler', strict: true, noEmit: true, lib: ['es2022', 'dom'] },
  include: ['src'],
}));
writeFileSync(join(out, 'index.html'), '<!doctype html><html><body style="margin:0"><canvas style="width:640px;height:480px"></canvas><script type="module" src="/src/app.ts"></script></body></html>\n');
writeFileSync(join(out, 'src', 'app.ts'), `import Tessera, { View, hasWebGL2 } from 'tessera-web';
const w = window as unknown as { appIdle?: unknown; appError?: string };
const canvas = document.querySelector('canvas') as HTMLCanvasElement;
const url = new URLSearchParams(location.search).get('model') ?? '';
if (!hasWebGL2()) w.appError = 'no WebGL2';
Tessera.view(canvas, { url, tolerancePx: 1 }).then((view: View) => {
  view.addEventListener('idle', () => { w.appIdle = view.stats; });
}).catch((e: unknown) => { w.appError = String(e); });
`);
writeFileSync(join(out, 'src', 'three-types.ts'), `import * as THREE from 'three';
import { TesseraModel, morphMaterial } from 'tessera-web/three';
export async function place(scene: THREE.Scene, camera: THREE.PerspectiveCamera): Promise<THREE.Vector3> {
  const model = await TesseraModel.load('/models/m.tsr', { tolerancePx: 2, memoryBytes: 256 << 20 });
  scene.add(model);
  morphMaterial(new THREE.MeshStandardMaterial());
  return model.homeView(camera).add(model.box.min);
}
`);
try {
  execFileSync(process.execPath, [join(out, 'node_modules', 'typescript', 'bin', 'tsc'), '-p', out], { encoding: 'utf8', stdio: 'pipe' });
  result.tsc = 'ok';
} catch (e) {
  result.tsc = String(e.stdout || e.message);
}
execFileSync(process.execPath, [join(out, 'node_modules', 'vite', 'bin', 'vite.js'), 'build', out, '--logLevel', 'error'], { cwd: out, stdio: 'pipe' });
const dist = join(out, 'dist');
const walk = (d, p = '') => readdirSync(d, { withFileTypes: true }).flatMap((e) => (e.isDirectory() ? walk(join(d, e.name), p + e.name + '/') : [p + e.name]));
result.files = walk(dist);

// A static host of the bundle (as any web server would serve it).
const types = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm' };
const server = createServer((req, res) => {
  const path = decodeURIComponent(new URL(req.url, 'http://x').pathname);
  const file = join(dist, path === '/' ? 'index.html' : path);
  if (!file.startsWith(dist) || !existsSync(file)) {
    res.writeHead(404).end();
    return;
  }
  res.writeHead(200, { 'content-type': types[extname(file)] || 'application/octet-stream' });
  res.end(readFileSync(file));
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const port = server.address().port;

const browser = await launchChromium({}, [], 'package-app.mjs');
try {
  const page = await browser.newPage({ viewport: { width: 700, height: 520 } });
  page.on('console', (m) => result.console.push(m.text()));
  page.on('pageerror', (e) => result.console.push(`pageerror: ${e}`));
  const t0 = Date.now();
  await page.goto(`http://127.0.0.1:${port}/?model=${encodeURIComponent(modelUrl)}`);
  result.outcome = 'timeout';
  while (Date.now() - t0 < 90000) {
    const r = await page.evaluate(() => ({ idle: window.appIdle ?? null, error: window.appError ?? null }));
    if (r.idle || r.error) {
      result.outcome = r.error ? 'error' : 'idle';
      result.stats = r.idle;
      result.error = r.error;
      break;
    }
    await new Promise((f) => setTimeout(f, 200));
  }
  result.ms = Date.now() - t0;
  await page.screenshot({ path: join(out, 'shot.png') });
} finally {
  await browser.close();
  server.close();
}
console.log(JSON.stringify(result));
