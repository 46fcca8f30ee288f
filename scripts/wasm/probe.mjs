// Runs the wasm build of the format reader + streaming core (wasm_probe.wasm, from
// scripts/check-wasm) under Node on a real model file: prints the triangles the last
// progressive frame drew, as "NODES TRIANGLES". Usage: node probe.mjs PROBE.wasm MODEL.tsr FRAMES
import { readFileSync } from 'node:fs';

const [wasmPath, modelPath, frames] = process.argv.slice(2);
const { instance } = await WebAssembly.instantiate(readFileSync(wasmPath), {});
const { memory, probe_alloc, probe_run } = instance.exports;
const model = readFileSync(modelPath);
const ptr = probe_alloc(model.length);
new Uint8Array(memory.buffer, ptr, model.length).set(model);
const r = probe_run(ptr, model.length, Number(frames || 30));
if (r < 0n) {
  console.error(`${modelPath}: the wasm reader could not parse the model`);
  process.exit(1);
}
console.log(`${r >> 32n} ${r & 0xffffffffn}`);
