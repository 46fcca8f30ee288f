// WebAssembly half of the selection timing (scripts/bench-web; the native half is
// src/bin/bench-frames.rs): the probe's Bench (lib.rs) over the model, warmed up over
// the orbit, then each scheduler frame timed around the call with performance.now().
// Prints one JSON object with the same fields as the native example.
//
//   node bench.mjs PROBE.wasm MODEL.tsr [frames 24] [passes 5] [width 1280] [height 720] [distance 2.0]
import { readFileSync } from 'node:fs';
import { performance } from 'node:perf_hooks';

const [wasmPath, modelPath, ...rest] = process.argv.slice(2);
const num = (i, d) => (rest[i] === undefined ? d : Number(rest[i]));
const [frames, passes, width, height, distance] = [num(0, 24), num(1, 5), num(2, 1280), num(3, 720), num(4, 2.0)];
const { instance } = await WebAssembly.instantiate(readFileSync(wasmPath), {});
const { memory, probe_alloc, probe_bench_open, probe_bench_warm, probe_bench_frame } = instance.exports;
let t = performance.now();
const model = readFileSync(modelPath);
const ptr = probe_alloc(model.length);
new Uint8Array(memory.buffer, ptr, model.length).set(model);
const read_ms = performance.now() - t;
t = performance.now();
const nodesInModel = probe_bench_open(ptr, model.length, frames, width, height, Math.round(distance * 100));
const open_ms = performance.now() - t;
if (nodesInModel < 0n) {
  console.error(`${modelPath}: the wasm reader could not parse the model`);
  process.exit(1);
}
t = performance.now();
const warm = probe_bench_warm();
const warm_ms = performance.now() - t;
const ms = [];
let nodes = 0n;
let tris = 0n;
for (let p = 0; p < passes; p++) {
  for (let k = 0; k < frames; k++) {
    const t0 = performance.now();
    const r = probe_bench_frame(k);
    ms.push(performance.now() - t0);
    nodes += r >> 32n;
    tris += r & 0xffffffffn;
  }
}
const n = ms.length;
const mean = ms.reduce((a, b) => a + b, 0) / n;
ms.sort((a, b) => a - b);
const q = (p) => ms[Math.round((n - 1) * p)];
const r4 = (x) => Math.round(x * 1e4) / 1e4;
console.log(
  JSON.stringify({
    target: 'wasm32 (Node ' + process.version + ')',
    model_nodes: Number(nodesInModel),
    read_ms: Math.round(read_ms * 10) / 10,
    open_ms: Math.round(open_ms * 10) / 10,
    warm_passes: warm > 0n ? Number(warm) : null,
    warm_ms: Math.round(warm_ms * 10) / 10,
    frames_timed: n,
    ms_per_frame_mean: r4(mean),
    ms_per_frame_median: r4(q(0.5)),
    ms_per_frame_p95: r4(q(0.95)),
    ms_per_frame_min: r4(ms[0]),
    ms_per_frame_max: r4(ms[n - 1]),
    drawn_nodes_mean: Math.round((Number(nodes) / n) * 10) / 10,
    triangles_mean: Math.round(Number(tris) / n),
    checksum: `${nodes}/${tris}`,
    wasm_memory_bytes: memory.buffer.byteLength,
  }),
);
