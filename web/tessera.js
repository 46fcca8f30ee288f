// Tessera in a web page: a small ES module over the WebAssembly viewer (crates/web,
// built with scripts/build-web into web/dist/ beside this file).
//
//   import { Tessera } from './tessera.js';
//   const v = await Tessera.view(canvas, { url, tolerancePx: 1, memoryBytes: 256 << 20 });
//   v.addEventListener('progress', (e) => console.log(e.detail.triangles));
//   v.addEventListener('idle', () => ...);      // the view converged: nothing pending
//   v.addEventListener('error', (e) => console.error(e.detail.message));
//   v.addEventListener('networkerror', (e) => ...);  // requests failed: e.detail.message;
//                   // what has loaded stays drawn, the requests are retried with backoff
//   v.addEventListener('networkrestored', () => ...);  // data arrives again
//   v.networkError;  // the message while requests fail, else null
//   v.addEventListener('warning', (e) => ...);  // part of the model cannot be shown (a
//                   // truncated file: e.detail.message); the rest is
//   v.warning;      // that message, else null
//   v.setCamera({ position, target, up, fov_y_deg, width, height });  // docs/camera.md
//   v.camera();     // the current camera (sized as the canvas)
//   await v.screenshot();  // a PNG Blob of the view at the canvas's pixel size
//   await v.pointAt(x, y);  // the point drawn under canvas pixel (x, y), or null
//   await v.pick(x, y);     // the full-resolution surface point under it ({point,
//                           // normal, distance, exact, ...}), or null
//   v.dispose();    // stops the frame loop, frees the GPU and wasm memory (and the
//                   // decode workers, with the page's last view)
//
// Fetched patches are decoded (and textures' mips made) in decode workers
// (tessera_worker.js beside this file: module workers running the same wasm module),
// shared by every view on the page; `workers: 0` decodes on the main thread instead.
//
// Tessera.view rejects with an Error whose message is meant for the page (no WebGL2, a
// 404 model, a server without Range support, a model of a newer format version).
// Mouse: left drag orbits, right / middle / shift-left drag pans, the wheel zooms
// toward the point under the cursor, a double-click moves the pivot onto it.
// Touch (Pointer Events, the canvas's touch-action set to none so the page does not
// scroll): one finger orbits, two fingers pinch to zoom (about the point under their
// centre) and drag to pan, a double tap recentres on the point under it.

import init, { Viewer } from './tessera_web.js';

let wasmReady = null;
let wasmModule = null;
let wasmMemory = null;

// The module compiled once: instantiated here and, the same compiled module, in each
// decode worker (no second download or compile).
async function compileWasm(url) {
  const resp = await fetch(url);
  if (!resp.ok) throw new Error(`cannot load ${url}: HTTP ${resp.status}`);
  if (typeof WebAssembly.compileStreaming === 'function') {
    try {
      return await WebAssembly.compileStreaming(resp.clone());
    } catch (_) {
      // Served without the application/wasm type: compiled from the bytes instead.
    }
  }
  return WebAssembly.compile(await resp.arrayBuffer());
}

/** Compiles and instantiates the wasm module once (for tessera-three.js too). */
export function loadWasm() {
  if (!wasmReady) {
    wasmReady = (async () => {
      const module = await compileWasm(new URL('./tessera_web_bg.wasm', import.meta.url));
      const wasm = await init({ module_or_path: module });
      wasmModule = module;
      wasmMemory = wasm.memory;
    })();
    wasmReady.catch(() => {
      wasmReady = null;
    });
  }
  return wasmReady;
}

/** Decode workers the page starts by default: the cores but one, 1 to 4. */
export function defaultWorkers() {
  const cores = (typeof navigator !== 'undefined' && navigator.hardwareConcurrency) || 2;
  return Math.min(4, Math.max(1, cores - 1));
}

// The page's decode workers (tessera_worker.js, module workers running the same wasm
// module), shared by every view on the page and stopped when the last is disposed.
// Each job goes to the worker with the fewest; a worker that fails to start or dies
// rejects its jobs, and the viewer then decodes on the main thread.
class DecodePool {
  #workers = [];
  #jobs = new Map();
  #next = 1;
  users = 0;
  failure = null;

  constructor(module, size) {
    for (let i = 0; i < size; i++) {
      let worker;
      try {
        worker = new Worker(new URL('./tessera_worker.js', import.meta.url), { type: 'module' });
      } catch (e) {
        this.failure = `decode workers cannot start here: ${(e && e.message) || e}`;
        break;
      }
      const entry = { worker, jobs: 0, heap: 0, dead: false };
      worker.onmessage = (e) => this.#message(entry, e.data);
      worker.onerror = (e) => {
        if (e && e.preventDefault) e.preventDefault();
        this.#die(entry, (e && e.message) || 'a decode worker failed to load');
      };
      worker.postMessage({ module });
      this.#workers.push(entry);
    }
  }

  /** Workers running. */
  get size() {
    return this.#workers.filter((w) => !w.dead).length;
  }

  /** The workers' wasm memory, bytes (as each last reported it). */
  get heapBytes() {
    return this.#workers.reduce((sum, w) => sum + (w.dead ? 0 : w.heap), 0);
  }

  /** A promise of the reply (Uint8Array) to `job` (a Uint8Array, its buffer moved). */
  decode(job) {
    const live = this.#workers.filter((w) => !w.dead);
    if (!live.length) return Promise.reject(new Error(this.failure || 'no decode workers'));
    const entry = live.reduce((a, b) => (b.jobs < a.jobs ? b : a));
    const id = this.#next++;
    return new Promise((resolve, reject) => {
      this.#jobs.set(id, { resolve, reject, entry });
      entry.jobs++;
      entry.worker.postMessage({ id, job }, [job.buffer]);
    });
  }

  #message(entry, m) {
    if (m.ready) return;
    if (m.initError) {
      this.#die(entry, `a decode worker could not start: ${m.initError}`);
      return;
    }
    const job = this.#jobs.get(m.id);
    if (!job) return;
    this.#jobs.delete(m.id);
    entry.jobs--;
    if (m.heap) entry.heap = m.heap;
    if (m.reply) job.resolve(m.reply);
    else job.reject(new Error(m.error));
  }

  #die(entry, message) {
    if (entry.dead) return;
    entry.dead = true;
    this.failure = message;
    entry.worker.terminate();
    for (const [id, job] of this.#jobs) {
      if (job.entry === entry) {
        this.#jobs.delete(id);
        job.reject(new Error(message));
      }
    }
  }

  terminate() {
    for (const entry of this.#workers) this.#die(entry, 'the decode workers were stopped');
  }
}

let pool = null;

/**
 * The page's decode workers (started on first use, `size` of them), or null (no
 * workers: `size` 0, or none here). Give each back with releasePool: the last one
 * stops them.
 */
export function acquirePool(size) {
  if (size <= 0 || typeof Worker === 'undefined' || !wasmModule) return null;
  if (!pool) pool = new DecodePool(wasmModule, size);
  pool.users++;
  return pool;
}

/** Gives back a pool of acquirePool (null: nothing). */
export function releasePool(p) {
  if (!p) return;
  p.users--;
  if (p.users <= 0) {
    p.terminate();
    if (pool === p) pool = null;
  }
}

/** Whether this browser gives a WebGL2 context (tried on a canvas of its own). */
export function hasWebGL2() {
  try {
    const c = document.createElement('canvas');
    return !!c.getContext('webgl2');
  } catch (_) {
    return false;
  }
}

function cameraJson(camera) {
  return typeof camera === 'string' ? camera : JSON.stringify(camera);
}

/** A model streaming into a canvas. Made by `Tessera.view`. */
export class View extends EventTarget {
  #viewer;
  #canvas;
  #raf = 0;
  #disposed = false;
  #stats = null;
  #idle = false;
  #convergedFrames = 0;
  #frameTimes = [];
  #listeners = [];
  #resizeObserver = null;
  #visibility = null;
  #shots = [];
  // Touch: the fingers down (pointerId -> canvas pixels) and the gesture they make
  // (null, or the fingers' count and, for two, their last spread).
  #touches = new Map();
  #gesture = null;
  // Fingers moved since the gesture last followed them (applied once a frame, so the
  // two fingers of a pinch move together: their separate events would pan back and
  // forth between them).
  #touchMoved = false;
  // Taps, for a double tap (recentre, as a double-click): where and when the current
  // one-finger touch began, and the last tap (position, end time).
  #tapStart = null;
  #lastTap = null;
  // pointAt() calls waiting for their answer (id -> resolve).
  #pointQueries = new Map();
  #nextQuery = 1;
  // Failed requests seen so far, and the network trouble going on (its message and
  // the bytes received when it began: more arriving means the server is back).
  #failedRequests = 0;
  #network = null;
  #warning = null;
  #url;

  #pool = null;

  constructor(viewer, canvas, autoResize, url = '', pool = null, pauseWhenHidden = true) {
    super();
    this.#url = url;
    this.#pool = pool;
    this.#viewer = viewer;
    this.#canvas = canvas;
    this.#bindInput();
    if (autoResize && typeof ResizeObserver !== 'undefined') {
      this.#resizeObserver = new ResizeObserver(() => this.#fit());
      this.#resizeObserver.observe(canvas);
    }
    // A canvas scrolled away (farther than half a screen) draws and fetches nothing
    // and gives the page's memory back to the views on screen (Viewer::set_visible).
    if (pauseWhenHidden && typeof IntersectionObserver !== 'undefined') {
      this.#visibility = new IntersectionObserver(
        (entries) => {
          if (this.#viewer) this.#viewer.set_visible(entries[entries.length - 1].isIntersecting);
        },
        { rootMargin: '50%' },
      );
      this.#visibility.observe(canvas);
    }
    this.#raf = requestAnimationFrame((t) => this.#frame(t));
  }

  /** The last frame's statistics (see crates/web/src/viewer.rs `frame`), plus fps. */
  get stats() {
    return this.#stats;
  }

  /**
   * While requests for the model fail (the server unreachable, the connection
   * dropped): a message for the page; null otherwise. The view keeps what it has
   * drawn and asks again with backoff ('networkerror' / 'networkrestored' events).
   */
  get networkError() {
    return this.#network ? this.#network.message : null;
  }

  /** Why part of the model cannot be shown (a truncated file), or null. */
  get warning() {
    return this.#warning;
  }

  /** Whether the view has converged (nothing pending, nothing moving). */
  get idle() {
    return this.#idle;
  }

  /** Moves to `camera` (an object or JSON string of docs/camera.md). */
  setCamera(camera) {
    this.#viewer.set_camera(cameraJson(camera));
  }

  /** The current camera (docs/camera.md), sized as the canvas. */
  camera() {
    return JSON.parse(this.#viewer.camera());
  }

  /**
   * The current view as a PNG `Blob`, at the canvas's pixel size (canvas.width x
   * canvas.height). A WebGL canvas is cleared once the browser has shown it, so the
   * view is drawn again and the canvas read in the same task, right after that frame.
   */
  screenshot() {
    return new Promise((resolve, reject) => {
      if (this.#disposed) {
        reject(new Error('screenshot: the view was disposed'));
        return;
      }
      this.#shots.push({ resolve, reject });
      this.#viewer.redraw();
    });
  }

  /**
   * The point drawn under canvas pixel (`x`, `y`) (canvas.width x canvas.height
   * pixels, top-left origin), in model coordinates: the depth of the last frame read
   * back and unprojected (the surface of the cut drawn, not the full-resolution pick).
   * Resolves to [x, y, z], or null over the background.
   */
  pointAt(x, y) {
    return new Promise((resolve, reject) => {
      if (this.#disposed) {
        reject(new Error('pointAt: the view was disposed'));
        return;
      }
      const id = this.#nextQuery++;
      this.#pointQueries.set(id, resolve);
      this.#viewer.point_at(id, x, y);
    });
  }

  /**
   * The point of the model's full-resolution surface under canvas pixel (`x`, `y`)
   * (canvas.width x canvas.height pixels, top-left origin), whatever the view draws:
   * the leaf patches under the ray are fetched as the pick needs them. Resolves to
   * { point: [x, y, z], normal, distance, node, triangle, exact, passes, patches,
   * bytes, ms } (model coordinates; exact: false when the index read so far shows no
   * deeper level there), or null when the ray misses the model.
   */
  pick(x, y) {
    if (this.#disposed) return Promise.reject(new Error('pick: the view was disposed'));
    return this.#viewer.pick(x, y);
  }

  /** Back to the home view. */
  reset() {
    this.#viewer.reset();
  }

  /** Changes the screen-space error tolerance, pixels. */
  setTolerance(px) {
    this.#viewer.set_tolerance_px(px);
  }

  /** Stops everything and frees the viewer's memory (GPU buffers, wasm heap). */
  dispose() {
    if (this.#disposed) return;
    this.#disposed = true;
    cancelAnimationFrame(this.#raf);
    for (const [target, type, fn, opts] of this.#listeners) target.removeEventListener(type, fn, opts);
    this.#listeners = [];
    if (this.#resizeObserver) this.#resizeObserver.disconnect();
    if (this.#visibility) this.#visibility.disconnect();
    this.#viewer.free();
    this.#viewer = null;
    releasePool(this.#pool);
    this.#pool = null;
    for (const s of this.#shots.splice(0)) s.reject(new Error('screenshot: the view was disposed'));
    for (const resolve of this.#pointQueries.values()) resolve(null);
    this.#pointQueries.clear();
  }

  // Reads the canvas just drawn (same task: before the browser composites and clears
  // it) into a PNG for the waiting screenshot() calls.
  #takeShots() {
    const shots = this.#shots.splice(0);
    try {
      this.#canvas.toBlob((blob) => {
        for (const s of shots) {
          if (blob) s.resolve(blob);
          else s.reject(new Error('screenshot: the canvas could not be encoded as PNG'));
        }
      }, 'image/png');
    } catch (e) {
      for (const s of shots) s.reject(e);
    }
  }

  // Requests that failed (network, server errors) are retried by the scheduler with
  // backoff, the coarser nodes drawn meanwhile; the page is told, and told again when
  // data arrives.
  #watchNetwork(stats) {
    const failed = stats.failed_requests || 0;
    if (failed > this.#failedRequests) {
      this.#failedRequests = failed;
      const first = !this.#network;
      this.#network = {
        bytes: stats.bytes_received,
        message:
          `network error: ${failed} request${failed === 1 ? '' : 's'} for ${this.#url || 'the model'} failed ` +
          '(the server is unreachable or dropped the connection); showing what has loaded, retrying',
      };
      if (first) this.dispatchEvent(new CustomEvent('networkerror', { detail: { message: this.#network.message, failedRequests: failed } }));
    } else if (this.#network && stats.bytes_received > this.#network.bytes) {
      this.#network = null;
      this.dispatchEvent(new CustomEvent('networkrestored', { detail: stats }));
    }
  }

  #fit() {
    if (this.#disposed) return;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(this.#canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(this.#canvas.clientHeight * dpr));
    if (w !== this.#canvas.width || h !== this.#canvas.height) {
      this.#canvas.width = w;
      this.#canvas.height = h;
    }
    this.#viewer.resize(w, h);
  }

  #on(target, type, fn, opts) {
    target.addEventListener(type, fn, opts);
    this.#listeners.push([target, type, fn, opts]);
  }

  #pixels(e) {
    const r = this.#canvas.getBoundingClientRect();
    const sx = r.width > 0 ? this.#canvas.width / r.width : 1;
    const sy = r.height > 0 ? this.#canvas.height / r.height : 1;
    return [(e.clientX - r.left) * sx, (e.clientY - r.top) * sy];
  }

  // The first two fingers: their centre and spread (canvas pixels).
  #twoFingers() {
    const [[ax, ay], [bx, by]] = this.#touches.values();
    return [(ax + bx) / 2, (ay + by) / 2, Math.hypot(bx - ax, by - ay)];
  }

  // Fingers came or went: the gesture running ends (inertia may carry it on) and one
  // for the fingers now down starts where they are, so nothing jumps.
  #touchRestart() {
    if (this.#gesture) this.#viewer.pointer_up();
    if (this.#gesture && this.#gesture.fingers === 2) this.#viewer.pinch_end();
    this.#gesture = null;
    if (this.#touches.size === 1) {
      const [[x, y]] = this.#touches.values();
      this.#viewer.pointer_down(0, x, y, false);
      this.#gesture = { fingers: 1 };
    } else if (this.#touches.size >= 2) {
      const [cx, cy, spread] = this.#twoFingers();
      this.#viewer.pointer_down(2, cx, cy, false);
      this.#gesture = { fingers: 2, spread };
    }
  }

  #touchMove() {
    const g = this.#gesture;
    if (!g || !this.#touchMoved) return;
    this.#touchMoved = false;
    if (g.fingers === 1) {
      const [[x, y]] = this.#touches.values();
      this.#viewer.pointer_move(x, y);
      return;
    }
    // Two fingers: their centre pans, their spread zooms about it.
    const [cx, cy, spread] = this.#twoFingers();
    this.#viewer.pointer_move(cx, cy);
    if (g.spread > 0 && spread > 0 && spread !== g.spread) this.#viewer.pinch(spread / g.spread, cx, cy);
    g.spread = spread;
  }

  // A one-finger touch that ended where it began, soon: a tap; two taps close in time
  // and place: a double tap, which recentres on the point under it (a double-click).
  #tap(e) {
    const start = this.#tapStart;
    this.#tapStart = null;
    if (!start || e.type !== 'pointerup' || this.#touches.size) return;
    const [x, y] = this.#pixels(e);
    const slop = 12 * (window.devicePixelRatio || 1);
    if (Math.hypot(x - start.x, y - start.y) > slop || e.timeStamp - start.t > 300) {
      this.#lastTap = null;
      return;
    }
    const last = this.#lastTap;
    if (last && e.timeStamp - last.t < 400 && Math.hypot(x - last.x, y - last.y) < 3 * slop) {
      this.#lastTap = null;
      this.#viewer.recentre_at(x, y);
      this.dispatchEvent(new CustomEvent('interact'));
    } else {
      this.#lastTap = { x, y, t: e.timeStamp };
    }
  }

  #bindInput() {
    const c = this.#canvas;
    // No scrolling or browser zoom on the canvas: touches are the view's.
    c.style.touchAction = 'none';
    this.#on(c, 'pointerdown', (e) => {
      if (this.#disposed) return;
      c.setPointerCapture(e.pointerId);
      const [x, y] = this.#pixels(e);
      if (e.pointerType === 'touch') {
        this.#touchMove(); // the moves so far, with the fingers they were made by
        this.#touches.set(e.pointerId, [x, y]);
        this.#tapStart = this.#touches.size === 1 ? { x, y, t: e.timeStamp } : null;
        this.#touchRestart();
      } else {
        this.#viewer.pointer_down(e.button, x, y, e.shiftKey);
      }
      this.dispatchEvent(new CustomEvent('interact'));
      e.preventDefault();
    });
    this.#on(c, 'pointermove', (e) => {
      if (this.#disposed) return;
      const [x, y] = this.#pixels(e);
      if (e.pointerType === 'touch') {
        if (!this.#touches.has(e.pointerId)) return;
        this.#touches.set(e.pointerId, [x, y]);
        this.#touchMoved = true;
      } else {
        this.#viewer.pointer_move(x, y);
      }
    });
    const up = (e) => {
      if (this.#disposed) return;
      if (c.hasPointerCapture(e.pointerId)) c.releasePointerCapture(e.pointerId);
      if (e.pointerType === 'touch') {
        if (this.#touches.has(e.pointerId)) {
          this.#touchMove();
          this.#touches.delete(e.pointerId);
          this.#touchRestart();
          this.#tap(e);
        }
      } else {
        this.#viewer.pointer_up();
      }
    };
    this.#on(c, 'pointerup', up);
    this.#on(c, 'pointercancel', up);
    this.#on(c, 'contextmenu', (e) => e.preventDefault());
    this.#on(c, 'dblclick', (e) => {
      if (this.#disposed) return;
      const [x, y] = this.#pixels(e);
      this.#viewer.recentre_at(x, y);
      this.dispatchEvent(new CustomEvent('interact'));
      e.preventDefault();
    });
    this.#on(
      c,
      'wheel',
      (e) => {
        if (this.#disposed) return;
        e.preventDefault();
        // One notch (100 px, or 3 lines) is one zoom step; positive zooms in.
        const px = e.deltaMode === 1 ? e.deltaY * 33 : e.deltaMode === 2 ? e.deltaY * 400 : e.deltaY;
        const [x, y] = this.#pixels(e);
        this.#viewer.wheel(-px / 100, x, y);
        this.dispatchEvent(new CustomEvent('interact'));
      },
      { passive: false },
    );
  }

  #frame(t) {
    if (this.#disposed) return;
    let stats;
    try {
      this.#touchMove();
      stats = JSON.parse(this.#viewer.frame(t));
    } catch (e) {
      const message = e && e.message ? e.message : String(e);
      this.#stats = { ...(this.#stats || {}), error: message, idle: false };
      this.#idle = false;
      this.dispatchEvent(new CustomEvent('error', { detail: { message } }));
      return; // the loop stops: a fatal streaming error
    }
    if (stats.drew) {
      this.#frameTimes.push(t);
      if (this.#shots.length) this.#takeShots();
    }
    while (this.#frameTimes.length && this.#frameTimes[0] < t - 1000) this.#frameTimes.shift();
    stats.fps = this.#frameTimes.length;
    // The page's wasm memory (every view's), and the decode workers'.
    stats.wasm_heap_bytes = wasmMemory ? wasmMemory.buffer.byteLength : 0;
    stats.worker_heap_bytes = this.#pool ? this.#pool.heapBytes : 0;
    for (const { id, point } of stats.picks || []) {
      const resolve = this.#pointQueries.get(id);
      this.#pointQueries.delete(id);
      if (resolve) resolve(point);
    }
    this.#stats = stats;
    this.#watchNetwork(stats);
    if (stats.warning && stats.warning !== this.#warning) {
      this.#warning = stats.warning;
      this.dispatchEvent(new CustomEvent('warning', { detail: { message: stats.warning } }));
    }
    // Idle once two frames in a row have converged: the last one drawn is on screen.
    this.#convergedFrames = stats.idle ? this.#convergedFrames + 1 : 0;
    const idle = this.#convergedFrames >= 2;
    if (idle !== this.#idle) {
      this.#idle = idle;
      if (idle) this.dispatchEvent(new CustomEvent('idle', { detail: stats }));
    }
    this.dispatchEvent(new CustomEvent('progress', { detail: stats }));
    this.#raf = requestAnimationFrame((t2) => this.#frame(t2));
  }
}

export const Tessera = {
  /**
   * Opens the model at `url` (served with HTTP Range support) in `canvas`.
   * Options: tolerancePx (default 1), memoryBytes (default 512 MiB: half GPU, a
   * quarter decoded patches; the views and three.js models of a page share one budget,
   * the largest of theirs, split each frame by what each view needs, none getting more
   * than its own; stats.page_models counts them), camera (docs/camera.md; default the home view),
   * autoResize (default true: the canvas follows its CSS size times devicePixelRatio;
   * false keeps canvas.width x canvas.height), prefixBytes (bytes of the first range
   * request, default 64 KiB: the header and the top of the index of most models),
   * maxTextureDim (default null: the device's own; a number makes the device's largest
   * texture that, at least the canvas's size, as on a smaller GPU: textured models'
   * larger patch textures are then uploaded from their first mip that fits),
   * workers (decode workers, default defaultWorkers(): the cores but one, 1 to 4,
   * shared by every view on the page; 0 decodes on the main thread, at most 6 ms a
   * frame), cancelRequests (default true: a range request none of whose patches the
   * view has wanted for 4 frames is aborted, so a turned camera does not wait behind
   * the bytes of the view it left; false lets every request finish), morph (default
   * true: geomorphing, a refinement blends in from its parent's shape; false draws
   * every patch at its own, so refinements pop), pauseWhenHidden (default true: while
   * the canvas is scrolled away, more than half a screen off, the view draws and
   * fetches nothing and its demand on the page's shared memory is 0; stats.hidden).
   */
  async view(
    canvas,
    { url, tolerancePx = 1, memoryBytes = 512 * 1048576, camera = null, autoResize = true, prefixBytes = 65536, maxTextureDim = null, workers = defaultWorkers(), cancelRequests = true, morph = true, pauseWhenHidden = true } = {},
  ) {
    if (!url) throw new Error('Tessera.view: no model URL given');
    if (!hasWebGL2()) {
      throw new Error(
        'This browser cannot draw with WebGL2: enable WebGL or hardware acceleration, or use a browser that has it.',
      );
    }
    await loadWasm();
    if (autoResize) {
      const dpr = window.devicePixelRatio || 1;
      canvas.width = Math.max(1, Math.round(canvas.clientWidth * dpr));
      canvas.height = Math.max(1, Math.round(canvas.clientHeight * dpr));
    }
    const abs = new URL(url, document.baseURI).href;
    const options = JSON.stringify({
      tolerancePx,
      memoryBytes,
      prefixBytes,
      maxTextureDim,
      cancelRequests,
      morph,
      camera: camera == null ? null : typeof camera === 'string' ? JSON.parse(camera) : camera,
    });
    const viewer = await Viewer.open(canvas, abs, options);
    const p = acquirePool(workers);
    if (p) viewer.set_decoder((job) => p.decode(job), p.size);
    return new View(viewer, canvas, autoResize, abs, p, pauseWhenHidden);
  },
};

export default Tessera;
