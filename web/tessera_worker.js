// A Tessera decode worker (started by tessera.js, a module worker beside it): the same
// WebAssembly module as the page, given to it compiled, runs `decode_job` on each
// fetched patch the viewer hands out (crates/web/src/wire.rs: the job's bytes in, the
// decoded patch with its texture's mip chain out, as one transferred buffer), so
// decoding never holds up a frame.
//
// Messages in:  { module: WebAssembly.Module }  once, first;
//               { id, job: Uint8Array }         each job (its buffer transferred).
// Messages out: { ready: true } or { initError }  once the module is instantiated;
//               { id, reply: Uint8Array, heap }  (the reply's buffer transferred; heap:
//                                                this worker's wasm memory, bytes);
//               { id, error }                   the job could not run at all.

import init, { decode_job } from './tessera_web.js';

let ready = null;
let memory = null;

self.onmessage = async (e) => {
  const m = e.data;
  if (m.module) {
    ready = init({ module_or_path: m.module }).then((wasm) => {
      memory = wasm.memory;
    });
    try {
      await ready;
      self.postMessage({ ready: true });
    } catch (err) {
      self.postMessage({ initError: String((err && err.message) || err) });
    }
    return;
  }
  try {
    if (!ready) throw new Error('the decode worker got a job before its module');
    await ready;
    const reply = decode_job(m.job);
    const heap = memory ? memory.buffer.byteLength : 0;
    self.postMessage({ id: m.id, reply, heap }, [reply.buffer]);
  } catch (err) {
    self.postMessage({ id: m.id, error: String((err && err.message) || err) });
  }
};
