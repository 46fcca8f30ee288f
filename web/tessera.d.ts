// Types of the Tessera browser module (tessera.js): a huge triangle mesh streamed from
// a .tsr file over HTTP range requests into a canvas (WebAssembly + WebGL2).

/** A camera of docs/camera.md (model coordinates). */
export interface TesseraCamera {
  position: [number, number, number];
  target: [number, number, number];
  up: [number, number, number];
  fov_y_deg: number;
  width: number;
  height: number;
}

/** Options of `Tessera.view`. */
export interface ViewOptions {
  /** The model's URL (served with HTTP Range support). */
  url: string;
  /** Screen-space error tolerance in pixels (default 1). */
  tolerancePx?: number;
  /** Memory budget in bytes (default 512 MiB: half GPU, a quarter decoded patches; shared by the page's views). */
  memoryBytes?: number;
  /** The first view (default: the home view framed by the model's roots). */
  camera?: TesseraCamera | string | null;
  /** The canvas follows its CSS size times devicePixelRatio (default true). */
  autoResize?: boolean;
  /** Bytes of the first range request (default 65536). */
  prefixBytes?: number;
  /** The device's largest texture as on a smaller GPU (default: the device's own). */
  maxTextureDim?: number | null;
  /** Decode workers (default: the cores but one, 1 to 4; 0 decodes on the main thread). */
  workers?: number;
  /** Abort range requests the view stopped wanting (default true). */
  cancelRequests?: boolean;
  /** Geomorphing (default true). */
  morph?: boolean;
  /** A canvas scrolled away draws and fetches nothing (default true). */
  pauseWhenHidden?: boolean;
}

/** The last frame's statistics (see crates/web/src/viewer.rs `frame`). */
export interface ViewStats {
  idle: boolean;
  frame: number;
  nodes: number;
  triangles: number;
  pending: number;
  bytes_received: number;
  requests: number;
  fps?: number;
  warning: string | null;
  [key: string]: unknown;
}

/** A full-resolution pick (`View.pick`). */
export interface Pick {
  point: [number, number, number];
  normal: [number, number, number];
  distance: number;
  node: number;
  triangle: number;
  exact: boolean;
  [key: string]: unknown;
}

/** A model streaming into a canvas; made by `Tessera.view`. Events: 'progress', 'idle', 'error', 'warning', 'networkerror', 'networkrestored' (CustomEvent, `detail` the stats or a message). */
export class View extends EventTarget {
  readonly stats: ViewStats | null;
  readonly networkError: string | null;
  readonly warning: string | null;
  readonly idle: boolean;
  setCamera(camera: TesseraCamera | string): void;
  camera(): TesseraCamera;
  screenshot(): Promise<Blob>;
  pointAt(x: number, y: number): Promise<[number, number, number] | null>;
  pick(x: number, y: number): Promise<Pick | null>;
  reset(): void;
  setTolerance(px: number): void;
  dispose(): void;
}

export declare const Tessera: {
  /** Opens the model at `options.url` in `canvas`. */
  view(canvas: HTMLCanvasElement, options: ViewOptions): Promise<View>;
};
export default Tessera;

/** Loads and compiles the WebAssembly module once (done by `Tessera.view`). */
export function loadWasm(): Promise<unknown>;
/** The decode workers a page gets by default: the cores but one, 1 to 4. */
export function defaultWorkers(): number;
/** Whether this browser can draw with WebGL2. */
export function hasWebGL2(): boolean;
