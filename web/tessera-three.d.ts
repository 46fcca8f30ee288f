// Types of the three.js adapter (tessera-three.js): a Tessera model streamed into a
// three.js scene as ordinary meshes.
import * as THREE from 'three';
import type { TesseraCamera } from './tessera.js';

/** Options of `TesseraModel.load`. */
export interface TesseraModelOptions {
  tolerancePx?: number;
  memoryBytes?: number;
  workers?: number;
  prefixBytes?: number;
  /** The page's largest texture (default 4096; pass renderer.capabilities.maxTextureSize). */
  maxTextureDim?: number;
  /** A material per patch (default: the adapter's own, morphing). */
  material?: ((patch: unknown) => THREE.Material) | null;
  /** Keep vertex and texel arrays on the JS heap (default true: raycasting works). */
  keepArrays?: boolean;
  morph?: boolean;
}

/** Patches a material so it blends each mesh toward its parent's shape by the node's ratio. */
export function morphMaterial<M extends THREE.Material>(material: M): M;

/** A streamed Tessera model: a THREE.Group of the patches drawn. Events: 'idle', 'error'. */
export class TesseraModel extends THREE.Group {
  static load(url: string, options?: TesseraModelOptions): Promise<TesseraModel>;
  /** Model coordinates of the patches' origin. */
  readonly origin: THREE.Vector3;
  /** The roots' box, model coordinates. */
  readonly box: THREE.Box3;
  readonly center: THREE.Vector3;
  readonly size: THREE.Vector3;
  readonly upAxis: string;
  readonly upVector: THREE.Vector3;
  readonly stats: Record<string, unknown> | null;
  readonly idle: boolean;
  readonly meshes: Map<number, THREE.Mesh>;
  setTolerancePx(px: number): void;
  setMemoryBytes(bytes: number): void;
  setMorph(enabled: boolean): void;
  cameraJson(renderer: THREE.WebGLRenderer, camera: THREE.PerspectiveCamera): TesseraCamera;
  homeView(camera: THREE.PerspectiveCamera, width?: number, height?: number): THREE.Vector3;
  update(renderer: THREE.WebGLRenderer, camera: THREE.PerspectiveCamera, timeMs?: number): Record<string, unknown>;
  dispose(): void;
}
export default TesseraModel;
