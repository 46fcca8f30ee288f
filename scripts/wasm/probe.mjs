// The browser module (DIST/tessera_web.js + tessera_web_bg.wasm, as scripts/build-web
// writes them) under Node, with no browser: its glue's initSync on the .wasm's bytes,
// then the module's probe functions (crates/web/src/probe.rs) on a model file.
//
//   node probe.mjs DIST imports
//       every import of the .wasm: each must come from the wasm-bindgen glue (the module
//       "./tessera_web_bg.js", a name its imports object defines). An `env.*` import is
//       what an unresolved C symbol (meshoptimizer, zstd) looks like: it fails here, and
//       in a browser. Prints "IMPORTS MODULES" (the count and the modules).
//   node probe.mjs DIST run MODEL.tsr FRAMES
//       probeRun: FRAMES progressive frames from a cold start; prints the last frame's
//       "NODES TRIANGLES" (scripts/check-wasm).
//   node probe.mjs DIST bench MODEL.tsr [frames 24] [passes 5] [width 1280] [height 720] [distance 2.0]
//       WebAssembly half of the selection timing (scripts/bench-web; the native half is
//       tessera-stream's examples/bench-frames.rs): ProbeBench over the model, warmed up
//       over the orbit, then each scheduler frame timed around the call with
//       performance.now(). Prints one JSON object with the same fields as the native one.
import { readFileSync } from 'node:fs';
import { join, resolve } from 'node:path';
import { pathToFileURL } from 'node:url';
import { performance } from 'node:perf_hooks';

const [dist, mode, modelPath, ...rest] = process.argv.slice(2);
const wasmBytes = readFileSync(join(dist, 'tessera_web_bg.wasm'));
const gluePath = join(dist, 'tessera_web.js');
const fail = (msg) => {
  console.error(`probe.mjs: ${msg}`);
  process.exit(1);
};

if (mode === 'imports') {
  const glue = readFileSync(gluePath, 'utf8');
  const imports = WebAssembly.Module.imports(new WebAssembly.Module(wasmBytes));
  const bad = imports.filter(
    (i) => i.module !== './tessera_web_bg.js' || !/^__wb(g|indgen)_/.test(i.name) || !glue.includes(`${i.name}:`),
  );
  if (bad.length) fail(`imports the wasm-bindgen glue does not provide: ${bad.map((i) => `${i.module}.${i.name}`).join(' ')}`);
  console.log(`${imports.length} ${[...new Set(imports.map((i) => i.module))].join(',') || 'none'}`);
  process.exit(0);
}

const web = await import(pathToFileURL(resolve(gluePath)).href);
const wasm = web.initSync({ module: wasmBytes });
let t = performance.now();
const model = readFileSync(modelPath);
const read_ms = performance.now() - t;

if (mode === 'run') {
  let r;
  try {
    r = web.probeRun(model, Number(rest[0] || 30));
  } catch (e) {
    fail(`${modelPath}: the wasm reader could not parse the model: ${e.message ?? e}`);
  }
  console.log(`${r[0]} ${r[1]}`);
} else if (mode === 'bench') {
  const num = (i, d) => (rest[i] === undefined ? d : Number(rest[i]));
  const [frames, passes, width, height, distance] = [num(0, 24), num(1, 5), num(2, 1280), num(3, 720), num(4, 2.0)];
  t = performance.now();
  let b;
  try {
    b = new web.ProbeBench(model, frames, width, height, distance);
  } catch (e) {
    fail(`${modelPath}: the wasm reader could not parse the model: ${e.message ?? e}`);
  }
  const open_ms = performance.now() - t;
  t = performance.now();
  const warm = b.warm();
  const warm_ms = performance.now() - t;
  const ms = [];
  let nodes = 0;
  let tris = 0;
  for (let p = 0; p < passes; p++) {
    for (let k = 0; k < frames; k++) {
      const t0 = performance.now();
      const drawn = b.frame(k);
      ms.push(performance.now() - t0);
      nodes += drawn;
      tris += b.triangles;
    }
  }
  const n = ms.length;
  const mean = ms.reduce((a, x) => a + x, 0) / n;
  ms.sort((a, x) => a - x);
  const q = (p) => ms[Math.round((n - 1) * p)];
  const r4 = (x) => Math.round(x * 1e4) / 1e4;
  console.log(
    JSON.stringify({
      target: 'wasm32 (Node ' + process.version + ', scripts/build-web module)',
      model_nodes: b.nodes(),
      read_ms: Math.round(read_ms * 10) / 10,
      open_ms: Math.round(open_ms * 10) / 10,
      warm_passes: warm ?? null,
      warm_ms: Math.round(warm_ms * 10) / 10,
      frames_timed: n,
      ms_per_frame_mean: r4(mean),
      ms_per_frame_median: r4(q(0.5)),
      ms_per_frame_p95: r4(q(0.95)),
      ms_per_frame_min: r4(ms[0]),
      ms_per_frame_max: r4(ms[n - 1]),
      drawn_nodes_mean: Math.round((nodes / n) * 10) / 10,
      triangles_mean: Math.round(tris / n),
      checksum: `${nodes}/${tris}`,
      wasm_memory_bytes: wasm.memory.buffer.byteLength,
    }),
  );
} else {
  fail('usage: node probe.mjs DIST imports | run MODEL.tsr FRAMES | bench MODEL.tsr [frames passes width height distance]');
}
