// Browser half of scripts/bench-web (issue 13 targets; not run in CI): drives Debian's
// headless Chromium (WebGL2 on SwiftShader) with playwright-core, as browser.mjs does,
// over a model served by `tessera serve --web`, and prints one JSON object.
//
//   node web/tests/bench-web.mjs PLAN.json > RESULT.json
//
// PLAN: {"chromium", "base": "http://ADDR", "model": "/models/NAME.tsr", "page": "index"
// (web/index.html, the tessera.js default memoryBytes) | "blank" (web/tests/blank.html:
// the driver calls Tessera.view itself with "memory_bytes"), "memory_bytes" (blank only),
// "camera" (docs/camera.md, with width and height: the still view and the canvas size),
// "orbit": [camera, ...], "workers" (decode workers: index.html's ?workers=N or
// Tessera.view's `workers`; null: the page's default), "timeout_ms"}.
//
// Two visits, each a fresh browser context (nothing cached):
//   "still": the page opened at `camera`; page-clock times (from navigation start) of
//     the first drawn frame with triangles (the roots) and of the view's convergence
//     (window.tesseraIdle, i.e. the complete cut's detail), the model bytes the viewer
//     received by then (stats.bytes_received) and everything the page fetched by then
//     (Resource Timing transferSize: HTML, JS, WASM, model ranges); then the "complete"
//     orbit: each camera set with setCamera and waited on until a frame after it has
//     converged (time per view, frames, bytes).
//   "progressive": opened at `camera`, waited to idle, then the orbit played one camera
//     per animation frame (requestAnimationFrame; the view never waits for data): the
//     intervals between those frames (the frame time), the main-thread time of each
//     Viewer.frame call (the wasm-bindgen method wrapped), bytes during the orbit, then
//     the time until the last view has converged.
// Both record every frame's statistics (tessera.js / crates/web/src/viewer.rs `frame`)
// through accessors on window.tesseraStats / window.tesseraIdle installed before the
// page runs: selection_ms, the decode and upload times (cumulative since open: decoded,
// decode_ms_total/max, uploads, upload_ms_total/max), gpu_bytes, ram_bytes; and per
// frame the JS heap (performance.memory, precise with --enable-precise-memory-info); the
// wasm memory (it only grows) and CDP Runtime.getHeapUsage at the end of each phase.
// Exit 0 when the visits ran (whatever their outcome), 2 on a driver failure.

import { readFileSync } from 'node:fs';
import { launchChromium } from './chromium.mjs';

const plan = JSON.parse(readFileSync(process.argv[2], 'utf8'));
const timeout = plan.timeout_ms || 300000;
const browser = await launchChromium(plan, ['--enable-precise-memory-info'], 'bench-web.mjs');

// Before any page script: every frame's statistics recorded as the page publishes them.
function recorder() {
  const B = (window.__bench = { frames: [], first: null, idle: null, heapPeak: 0, gpuPeak: 0, ramPeak: 0 });
  performance.setResourceTimingBufferSize(1000000);
  const netBytes = () => {
    let n = 0;
    for (const e of performance.getEntriesByType('navigation')) n += e.transferSize || 0;
    for (const e of performance.getEntriesByType('resource')) n += e.transferSize || 0;
    return n;
  };
  B.netBytes = netBytes;
  // The fixed fields, plus whatever the build publishes about decoding, uploads, decode
  // workers and heaps (the web-worker change adds worker_decoded, worker_decode_ms_mean,
  // decode_workers, wasm_heap_bytes, worker_heap_bytes, ...).
  const extra = (s) => {
    const o = {};
    for (const [k, v] of Object.entries(s)) if (typeof v === 'number' && /decode|upload|worker|heap|at_workers/.test(k)) o[k] = v;
    return o;
  };
  const pick = (s) => ({
    ...extra(s),
    frame: s.frame, drew: s.drew, idle: s.idle, nodes: s.nodes, triangles: s.triangles,
    bytes_received: s.bytes_received, requests: s.requests, pending: s.pending,
    selection_ms: s.selection_ms, decoded: s.decoded, decode_ms_total: s.decode_ms_total,
    decode_ms_max: s.decode_ms_max, uploads: s.uploads, upload_ms_total: s.upload_ms_total,
    upload_ms_max: s.upload_ms_max, textured_uploads: s.textured_uploads,
    textured_upload_ms_mean: s.textured_upload_ms_mean, gpu_bytes: s.gpu_bytes,
    gpu_budget_bytes: s.gpu_budget_bytes, ram_bytes: s.ram_bytes, index_bytes: s.index_bytes,
    index_nodes: s.index_nodes, model_nodes: s.model_nodes, first_frame_ms: s.first_frame_ms,
    converged_ms: s.converged_ms, adapter: s.adapter,
  });
  B.pick = pick;
  let stats = null;
  let idle = false;
  Object.defineProperty(window, 'tesseraStats', {
    configurable: true,
    get: () => stats,
    set: (s) => {
      stats = s;
      const t = performance.now();
      const heap = performance.memory ? performance.memory.usedJSHeapSize : 0;
      B.heapPeak = Math.max(B.heapPeak, heap);
      B.gpuPeak = Math.max(B.gpuPeak, s.gpu_bytes || 0);
      B.ramPeak = Math.max(B.ramPeak, s.ram_bytes || 0);
      B.wasmPeak = Math.max(B.wasmPeak || 0, s.wasm_heap_bytes || 0);
      B.workerHeapPeak = Math.max(B.workerHeapPeak || 0, s.worker_heap_bytes || 0);
      B.frames.push({ t, heap, ...pick(s) });
      if (!B.first && s.drew && s.triangles > 0) B.first = { ms: t, net_bytes: netBytes(), stats: pick(s) };
    },
  });
  Object.defineProperty(window, 'tesseraIdle', {
    configurable: true,
    get: () => idle,
    set: (v) => {
      idle = v;
      if (v && !B.idle && stats) B.idle = { ms: performance.now(), net_bytes: netBytes(), stats: pick(stats) };
    },
  });
}

// In the page: opens the view on blank.html as index.html would (its stats published on
// window.tesseraStats / tesseraIdle), with the given memory budget.
async function openBlank({ model, camera, memory, workers }) {
  const { Tessera } = await import('./tessera.js');
  const c = document.createElement('canvas');
  c.id = 'view';
  c.width = camera.width;
  c.height = camera.height;
  c.style.width = camera.width + 'px';
  c.style.height = camera.height + 'px';
  document.body.style.margin = '0';
  document.body.appendChild(c);
  try {
    const opts = { url: model, camera, autoResize: false, memoryBytes: memory };
    if (workers != null) opts.workers = workers;
    const v = await Tessera.view(c, opts);
    window.tesseraView = v;
    v.addEventListener('progress', (e) => {
      window.tesseraStats = e.detail;
      window.tesseraIdle = v.idle;
    });
    v.addEventListener('idle', () => { window.tesseraIdle = true; });
    v.addEventListener('error', (e) => { window.tesseraError = e.detail.message; });
  } catch (e) {
    window.tesseraError = e.message;
  }
}

// In the page: wraps Viewer.frame (the wasm-bindgen class, the module instance the page
// uses) to time each call on the main thread.
async function wrapFrame() {
  const m = await import('./tessera_web.js');
  const proto = m.Viewer.prototype;
  if (proto.__benchWrapped) return;
  const orig = proto.frame;
  window.__frameMs = [];
  proto.frame = function (t) {
    const t0 = performance.now();
    try {
      return orig.call(this, t);
    } finally {
      window.__frameMs.push(performance.now() - t0);
    }
  };
  proto.__benchWrapped = true;
}

async function memory(page, cdp) {
  await cdp.send('HeapProfiler.collectGarbage').catch(() => {});
  const h = await cdp.send('Runtime.getHeapUsage').catch(() => ({}));
  const wasm = await page.evaluate(async () => (await (await import('./tessera_web.js')).default()).memory.buffer.byteLength);
  const b = await page.evaluate(() => {
    const B = window.__bench;
    return { heapPeak: B.heapPeak, gpuPeak: B.gpuPeak, ramPeak: B.ramPeak, wasmPeak: B.wasmPeak, workerHeapPeak: B.workerHeapPeak };
  });
  // Decode workers (if the build has them): their wasm memory as the stats report it.
  return {
    js_heap_used_after_gc: h.usedSize, js_heap_total: h.totalSize, js_heap_peak_sampled: b.heapPeak,
    wasm_memory_bytes: Math.max(wasm, b.wasmPeak || 0), worker_heap_peak: b.workerHeapPeak || 0,
    workers: page.workers().length, gpu_bytes_peak: b.gpuPeak, ram_bytes_peak: b.ramPeak,
  };
}

async function open(name) {
  const [w, h] = [plan.camera.width, plan.camera.height];
  const context = await browser.newContext({ viewport: { width: w + 400, height: h }, deviceScaleFactor: 1 });
  await context.addInitScript(recorder);
  const page = await context.newPage();
  const consoleLines = [];
  page.on('console', (m) => { if (m.type() === 'error' || m.type() === 'warning') consoleLines.push(`${m.type()}: ${m.text()}`); });
  page.on('pageerror', (e) => consoleLines.push(`pageerror: ${e.message}`));
  const cdp = await context.newCDPSession(page);
  if (plan.page === 'blank') {
    await page.goto(`${plan.base}/blank.html`);
    await page.evaluate(wrapFrame);
    await page.evaluate(openBlank, { model: plan.model, camera: plan.camera, memory: plan.memory_bytes, workers: plan.workers ?? null });
  } else {
    const workers = plan.workers == null ? '' : `&workers=${plan.workers}`;
    const url = `${plan.base}/?model=${encodeURIComponent(plan.model)}${workers}#camera=${encodeURIComponent(JSON.stringify(plan.camera))}`;
    await page.goto(url);
    await page.evaluate(wrapFrame);
  }
  const outcome = await page
    .waitForFunction(() => (window.tesseraError ? 'error' : window.__bench.idle ? 'idle' : false), null, { timeout, polling: 50 })
    .then((h) => h.jsonValue())
    .catch((e) => { consoleLines.push(`driver: ${e.message.split('\n')[0]}`); return 'timeout'; });
  const load = await page.evaluate(() => ({
    first: window.__bench.first,
    idle: window.__bench.idle,
    error: window.tesseraError || null,
    frames_to_idle: window.__bench.frames.length,
    net_requests: performance.getEntriesByType('resource').length,
    js_heap_peak_sampled: window.__bench.heapPeak,
    // Every frame until now: [ms, triangles, nodes, pending, bytes_received, idle].
    timeline: window.__bench.frames.map((f) => [Math.round(f.t), f.triangles, f.nodes, f.pending, f.bytes_received, f.idle ? 1 : 0]),
  }));
  return { name, context, page, cdp, outcome, load, consoleLines };
}

// In the page: each camera set, then the first frame after it that has converged.
async function completeOrbit({ orbit, timeout }) {
  const v = window.tesseraView;
  const B = window.__bench;
  const steps = [];
  for (const cam of orbit) {
    const f0 = v.stats.frame;
    const b0 = v.stats.bytes_received;
    const n0 = B.frames.length;
    const ms0 = window.__frameMs.length;
    const t0 = performance.now();
    v.setCamera(cam);
    const s = await new Promise((resolve, reject) => {
      const timer = setTimeout(() => reject(new Error('no convergence')), timeout);
      const on = (e) => {
        if (e.detail.frame > f0 && e.detail.idle) {
          clearTimeout(timer);
          v.removeEventListener('progress', on);
          resolve(e.detail);
        }
      };
      v.addEventListener('progress', on);
    });
    const frames = B.frames.slice(n0);
    const fm = window.__frameMs.slice(ms0);
    steps.push({
      ms: performance.now() - t0,
      frames: frames.length,
      drawn: frames.filter((f) => f.drew).length,
      bytes: s.bytes_received - b0,
      nodes: s.nodes,
      triangles: s.triangles,
      selection_ms_mean: frames.reduce((a, f) => a + (f.selection_ms || 0), 0) / Math.max(1, frames.length),
      frame_call_ms_mean: fm.reduce((a, x) => a + x, 0) / Math.max(1, fm.length),
      frame_call_ms_max: Math.max(0, ...fm),
    });
  }
  return { steps, end: B.pick(v.stats) };
}

// In the page: one orbit camera per animation frame, then wait for convergence.
async function progressiveOrbit({ orbit, timeout }) {
  const v = window.tesseraView;
  const B = window.__bench;
  const b0 = v.stats.bytes_received;
  const n0 = B.frames.length;
  const ms0 = window.__frameMs.length;
  const times = [];
  await new Promise((resolve) => {
    let k = 0;
    const step = (t) => {
      times.push(t);
      if (k < orbit.length) {
        v.setCamera(orbit[k++]);
        requestAnimationFrame(step);
      } else resolve();
    };
    requestAnimationFrame(step);
  });
  const tEnd = performance.now();
  const frames = B.frames.slice(n0);
  const fm = window.__frameMs.slice(ms0);
  const end = v.stats;
  const bytesOrbit = end.bytes_received - b0;
  const f0 = end.frame;
  const s = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error('no convergence')), timeout);
    const check = (e) => {
      if (e.detail.idle && e.detail.frame >= f0) {
        clearTimeout(timer);
        v.removeEventListener('progress', check);
        resolve(e.detail);
      }
    };
    v.addEventListener('progress', check);
  });
  const intervals = times.slice(1).map((t, i) => t - times[i]);
  return {
    intervals,
    frame_calls_ms: fm,
    frames: frames.map((f) => ({ drew: f.drew, nodes: f.nodes, triangles: f.triangles, selection_ms: f.selection_ms, pending: f.pending })),
    bytes_during: bytesOrbit,
    converge_ms: performance.now() - tEnd,
    bytes_to_converge: s.bytes_received - b0,
    end: B.pick(s),
  };
}

const out = { plan: { page: plan.page, model: plan.model, memory_bytes: plan.memory_bytes ?? null, workers: plan.workers ?? null, canvas: [plan.camera.width, plan.camera.height], orbit_frames: plan.orbit.length } };
try {
  const a = await open('still');
  out.still = { outcome: a.outcome, ...a.load };
  if (a.outcome === 'idle') {
    out.still.memory_at_idle = await memory(a.page, a.cdp);
    try {
      out.complete = await a.page.evaluate(completeOrbit, { orbit: plan.orbit, timeout });
      out.complete.memory = await memory(a.page, a.cdp);
    } catch (e) {
      out.complete = { error: e.message.split('\n')[0] };
    }
  }
  out.still.console = a.consoleLines;
  await a.context.close();

  const b = await open('progressive');
  out.progressive = { outcome: b.outcome };
  if (b.outcome === 'idle') {
    try {
      Object.assign(out.progressive, await b.page.evaluate(progressiveOrbit, { orbit: plan.orbit, timeout }));
      out.progressive.memory = await memory(b.page, b.cdp);
    } catch (e) {
      out.progressive.error = e.message.split('\n')[0];
    }
  }
  out.progressive.console = b.consoleLines;
  await b.context.close();
} catch (e) {
  console.error(`bench-web.mjs: ${e.stack || e.message}`);
  await browser.close();
  process.exit(2);
}
await browser.close();
process.stdout.write(JSON.stringify(out, null, 1) + '\n');
