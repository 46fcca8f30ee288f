// The three.js adapter: a Tessera model streamed into an existing three.js scene, its
// patches as ordinary THREE.Mesh objects (so they compose with the page's own objects,
// lights, controls and post-processing). Selection, fetching, budgets and decoding are
// the Rust code of the canvas viewer (crates/web's `Stream`: the same reader, fetch
// plan, decode workers and scheduler); this module only turns the patches it makes
// resident into meshes and shows the scheduler's draw list.
//
//   import * as THREE from 'three';              // the page's import map supplies three
//   import { TesseraModel } from './tessera-three.js';
//   const model = await TesseraModel.load(url, { tolerancePx: 1, memoryBytes: 256 << 20 });
//   scene.add(model);
//   model.homeView(camera);                      // optional: the desktop's home view
//   renderer.setAnimationLoop(() => {
//     model.update(renderer, camera);            // before each render: explicit, once a frame
//     renderer.render(scene, camera);
//   });
//   model.addEventListener('idle', (e) => ...);  // converged: nothing pending (e.stats)
//   model.addEventListener('error', (e) => ...); // streaming stopped (e.message)
//   model.stats;                                 // {triangles, nodes, pending, resident_bytes, meshes, ...}
//   model.setTolerancePx(2); model.setMemoryBytes(128 << 20);  // at run time
//   model.setMorph(false);                       // geomorphing off (on by default)
//   model.dispose();                             // frees every geometry, texture, material
//
// Coordinates: the object's local frame is the model's own coordinates (those of the
// input mesh). Its meshes hold f32 positions relative to `model.origin` (the model's
// bounding-sphere centre) in an inner group placed there, so a georeferenced model keeps
// its precision (three.js composes the model-view matrix in f64 on the CPU). Move,
// rotate or uniformly scale the TesseraModel like any object: the view is selected from
// the camera as seen in the model's frame, and the tolerance stays in screen pixels.
// `model.center`, `model.size` (of the roots' box), `model.upAxis` and `model.upVector`
// (the guessed up direction) help placing it.
//
// Geomorphing (GoLD), as the canvas viewer: a patch that refines its parent comes in
// at its parent's shape and blends to its own, and one coarsening out blends back, so
// nothing pops. Each mesh carries its vertices' morph targets (attributes
// `tesseraTarget`, `tesseraTargetNormal`, `tesseraTargetColor` or `tesseraTargetUv`:
// the positions, normals, colours and texture coordinates they take in the parent's
// shape, found by the GPU cache's own lookup in crates/render) and its material blends
// toward them by the node's ratio (uniform `tesseraRatio`: 0 its own shape, 1 its
// parent's), patched into three.js's standard shader (`morphMaterial`). Textured
// patches also sample no finer than their parent's texel detail while they morph
// (`tesseraMinLod`), as the native shader. Not done here: depth-based picking (use
// three.js raycasting on the meshes: it sees each mesh at its own shape).
//
// Materials: untextured models share one MeshStandardMaterial (vertex colours when the
// model has them, converted to linear as three.js expects; else a clay colour), and a
// mesh takes a morphing copy of it (one shader program for all) only while its ratio is
// above 0; textured models get one per patch with its texture (sRGB, mipmapped by
// WebGL), morphing. Pass `material: (patch) => THREE.Material` to make your own
// (disposed with its mesh unless it is `shared`: the same material for every patch,
// disposed by dispose()); those are drawn at their own shape unless you pass them
// through `morphMaterial` yourself.

import * as THREE from 'three';
import { Stream } from './tessera_web.js';
// The wasm module (compiled once) and the page's decode workers are tessera.js's: one
// pool shared by every canvas view and three.js model on the page.
import { loadWasm, defaultWorkers, acquirePool, releasePool } from './tessera.js';

const CLAY = new THREE.Color().setRGB(0.78, 0.74, 0.68, THREE.SRGBColorSpace);
const AXES = { '+x': [1, 0, 0], '-x': [-1, 0, 0], '+y': [0, 1, 0], '-y': [0, -1, 0], '+z': [0, 0, 1], '-z': [0, 0, -1] };

const _v = new THREE.Vector3();
const _d = new THREE.Vector3();
const _u = new THREE.Vector3();
const _size = new THREE.Vector2();
const _inv = new THREE.Matrix4();

// The morph, patched into three.js's own chunks (r187 names; the injected lines are
// written against `position`, `normal`, `color` and `uv` as three.js declares them).
const MORPH_VERTEX = {
  '#include <common>': `#include <common>
attribute vec3 tesseraTarget;
attribute vec3 tesseraTargetNormal;
uniform float tesseraRatio;
#ifdef USE_COLOR
attribute vec3 tesseraTargetColor;
#endif
#ifdef USE_MAP
attribute vec2 tesseraTargetUv;
#endif`,
  // a + (b - a) * r, as the native shader: a vertex whose target is itself stays
  // bit-exact at every ratio, so neighbours morphing at different ratios meet there.
  '#include <begin_vertex>': 'vec3 transformed = position + (tesseraTarget - position) * tesseraRatio;',
  '#include <beginnormal_vertex>': 'vec3 objectNormal = normal + (tesseraTargetNormal - normal) * tesseraRatio;',
  '#include <color_vertex>': `#include <color_vertex>
#if defined( USE_COLOR ) && !defined( USE_COLOR_ALPHA )
  vColor.rgb = color + (tesseraTargetColor - color) * tesseraRatio;
#endif`,
  '#include <uv_vertex>': `#include <uv_vertex>
#ifdef USE_MAP
  vMapUv = ( mapTransform * vec3( uv + (tesseraTargetUv - uv) * tesseraRatio, 1 ) ).xy;
#endif`,
};
// The texture sampled no finer than mip level `tesseraMinLod` (ratio x the levels
// between the patch's texels and its parent's): the derivatives scaled up to it, as
// crates/render/src/patch.wgsl's fs_textured; at 0 exactly three.js's own sampling.
const MORPH_FRAGMENT = {
  '#include <common>': `#include <common>
uniform float tesseraMinLod;`,
  '#include <map_fragment>': `#ifdef USE_MAP
  vec2 tesseraDx = dFdx( vMapUv );
  vec2 tesseraDy = dFdy( vMapUv );
  vec2 tesseraSize = vec2( textureSize( map, 0 ) );
  float tesseraRho = max( length( tesseraDx * tesseraSize ), length( tesseraDy * tesseraSize ) );
  float tesseraFloor = exp2( tesseraMinLod );
  float tesseraK = ( tesseraMinLod > 0.0 && tesseraRho < tesseraFloor ) ? tesseraFloor / max( tesseraRho, 1e-8 ) : 1.0;
  vec4 sampledDiffuseColor = textureGrad( map, vMapUv, tesseraDx * tesseraK, tesseraDy * tesseraK );
  diffuseColor *= sampledDiffuseColor;
#endif`,
};

function patchChunks(source, chunks) {
  for (const [from, to] of Object.entries(chunks)) {
    if (!source.includes(from)) throw new Error(`tessera-three: three.js shader chunk ${from} not found (three.js version?)`);
    source = source.replace(from, to);
  }
  return source;
}

/**
 * Makes `material` (a three.js built-in material using three's standard shader chunks,
 * e.g. MeshStandardMaterial) draw a Tessera patch morphed: its vertices blended toward
 * the mesh's `tesseraTarget*` attributes by `material.userData.tesseraRatio.value`.
 * Returns the material. Every material made so shares one shader program per kind.
 */
export function morphMaterial(material) {
  const ratio = { value: 0 };
  const minLod = { value: 0 };
  material.userData.tesseraRatio = ratio;
  material.userData.tesseraMinLod = minLod;
  material.onBeforeCompile = (shader) => {
    shader.uniforms.tesseraRatio = ratio;
    shader.uniforms.tesseraMinLod = minLod;
    shader.vertexShader = patchChunks(shader.vertexShader, MORPH_VERTEX);
    shader.fragmentShader = patchChunks(shader.fragmentShader, MORPH_FRAGMENT);
  };
  material.customProgramCacheKey = () => 'tessera-morph-1';
  return material;
}

/** A streamed Tessera model: a THREE.Group of the patches drawn. See the top of the file. */
export class TesseraModel extends THREE.Group {
  #stream;
  #workers;
  #content = new THREE.Group();
  #meshes = new Map();
  #shared = null;
  #sharedParams = null;
  #makeMaterial;
  #stats = null;
  #idleFrames = 0;
  #idle = false;
  #failed = null;
  #disposed = false;
  #radius;
  #keepArrays;

  /**
   * Opens the model at `url` (HTTP Range support needed). Options: tolerancePx
   * (default 1), memoryBytes (default 512 MiB: half for the meshes' arrays and
   * textures, a quarter for decoded patches waiting; shared with the page's other
   * models and views as Tessera.view's), workers (decode workers, default
   * the cores but one, 1 to 4; 0 decodes on the main thread, at most 6 ms a frame),
   * prefixBytes (first request, default 64 KiB), maxTextureDim (default 4096: larger
   * patch textures are handed over from their first mip that fits; pass
   * renderer.capabilities.maxTextureSize), material (see the top of the file),
   * keepArrays (default true; false drops each mesh's vertex and texel arrays from the
   * JS heap once WebGL has them: half the memory, but no raycasting on the meshes),
   * morph (default true: geomorphing; see the top of the file).
   */
  static async load(url, { tolerancePx = 1, memoryBytes = 512 * 1048576, workers = defaultWorkers(), prefixBytes = 65536, maxTextureDim = 4096, material = null, keepArrays = true, morph = true } = {}) {
    if (!url) throw new Error('TesseraModel.load: no model URL given');
    await loadWasm();
    const abs = new URL(url, typeof document !== 'undefined' ? document.baseURI : undefined).href;
    const stream = await Stream.open(abs, JSON.stringify({ tolerancePx, memoryBytes, prefixBytes, maxTextureDim, morph }));
    const pool = acquirePool(workers);
    if (pool) stream.set_decoder((job) => pool.decode(job), pool.size);
    return new TesseraModel(stream, pool, material, keepArrays);
  }

  constructor(stream, workers, material, keepArrays = true) {
    super();
    this.#keepArrays = keepArrays;
    this.name = 'TesseraModel';
    this.#stream = stream;
    this.#workers = workers;
    this.#makeMaterial = material;
    const o = stream.origin();
    /** Model coordinates of the patches' origin (the inner group's position). */
    this.origin = new THREE.Vector3(o[0], o[1], o[2]);
    const b = stream.bounds();
    /** The roots' box, model coordinates. */
    this.box = new THREE.Box3(new THREE.Vector3(b[0], b[1], b[2]), new THREE.Vector3(b[3], b[4], b[5]));
    this.center = this.box.getCenter(new THREE.Vector3());
    this.size = this.box.getSize(new THREE.Vector3());
    /** The model's guessed up axis ('+y', '+z', ...) and its direction. */
    this.upAxis = stream.up_axis();
    this.upVector = new THREE.Vector3().fromArray(AXES[this.upAxis] || [0, 1, 0]);
    this.#radius = Math.max(this.size.length() / 2, 1e-9);
    this.#content.name = 'TesseraModel patches';
    this.#content.position.copy(this.origin);
    this.add(this.#content);
  }

  /** The last frame's statistics (crates/web/src/stream.rs `frame`) plus `meshes`. */
  get stats() {
    return this.#stats;
  }

  /** Whether the view converged (two frames in a row with nothing pending). */
  get idle() {
    return this.#idle;
  }

  /** The meshes made (resident patches), by node. */
  get meshes() {
    return this.#meshes;
  }

  /** Changes the screen-space tolerance (pixels). */
  setTolerancePx(px) {
    this.#stream.set_tolerance_px(px);
  }

  /**
   * Changes the memory budget (bytes, split as in load()): lowering it evicts meshes
   * down to it at the next update() (unused ones first, then the drawn cut coarsened).
   */
  setMemoryBytes(bytes) {
    this.#stream.set_memory_bytes(bytes);
  }

  /** Turns geomorphing on or off (from the next update()). */
  setMorph(enabled) {
    this.#stream.set_morph(!!enabled);
  }

  /**
   * `camera` (a PerspectiveCamera) as a Tessera camera (docs/camera.md): model
   * coordinates, the renderer's drawing-buffer size, the effective vertical field of
   * view (zoom included).
   */
  cameraJson(renderer, camera) {
    this.updateWorldMatrix(true, false);
    camera.updateWorldMatrix(true, false);
    _inv.copy(this.matrixWorld).invert();
    const eye = camera.getWorldPosition(_v);
    const dir = camera.getWorldDirection(_d);
    _u.set(0, 1, 0).applyQuaternion(camera.getWorldQuaternion(new THREE.Quaternion()));
    const dist = Math.max(this.#radius, eye.distanceTo(this.localToWorld(this.center.clone())) * 1e-3);
    const target = eye.clone().addScaledVector(dir, dist).applyMatrix4(_inv);
    const up = _u.clone().transformDirection(_inv);
    eye.applyMatrix4(_inv);
    renderer.getDrawingBufferSize(_size);
    const fov = (2 * Math.atan(Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2) / (camera.zoom || 1)) * 180) / Math.PI;
    return {
      position: eye.toArray(),
      target: target.toArray(),
      up: up.toArray(),
      fov_y_deg: fov,
      width: Math.max(1, Math.round(_size.x)),
      height: Math.max(1, Math.round(_size.y)),
    };
  }

  /**
   * Puts `camera` at the desktop viewer's home view (framed by the roots, the model's
   * up axis) as placed in the scene; returns the point looked at (world coordinates:
   * an OrbitControls target).
   */
  homeView(camera, width = 1280, height = 720) {
    const c = JSON.parse(this.#stream.home_camera(width, height));
    this.updateWorldMatrix(true, false);
    const pos = this.localToWorld(new THREE.Vector3().fromArray(c.position));
    const target = this.localToWorld(new THREE.Vector3().fromArray(c.target));
    const up = new THREE.Vector3().fromArray(c.up).transformDirection(this.matrixWorld);
    camera.position.copy(pos);
    camera.up.copy(up);
    camera.fov = c.fov_y_deg;
    camera.lookAt(target);
    camera.updateProjectionMatrix();
    return target;
  }

  /**
   * One streaming step for `camera` (a PerspectiveCamera) drawn by `renderer`: call it
   * once a frame before renderer.render. Patches fetched and decoded since are made
   * into meshes, evicted ones disposed, and the meshes of the scheduler's draw list
   * shown. Returns the statistics.
   */
  update(renderer, camera, timeMs = performance.now()) {
    if (this.#disposed || this.#failed) return this.#stats;
    let stats;
    try {
      stats = JSON.parse(this.#stream.frame(JSON.stringify(this.cameraJson(renderer, camera)), timeMs));
    } catch (e) {
      this.#failed = (e && e.message) || String(e);
      this.dispatchEvent({ type: 'error', message: this.#failed });
      return this.#stats;
    }
    for (const node of this.#stream.take_removed()) this.#drop(node);
    for (const node of this.#stream.take_added()) {
      this.#drop(node);
      const patch = this.#stream.take_patch(node);
      if (patch) this.#make(node, patch);
    }
    const drawn = this.#stream.draw();
    const ratios = this.#stream.ratios();
    for (const mesh of this.#meshes.values()) mesh.visible = false;
    let morphing = 0;
    for (let k = 0; k < drawn.length; k++) {
      const mesh = this.#meshes.get(drawn[k]);
      if (!mesh) continue;
      mesh.visible = true;
      if (this.#setRatio(mesh, mesh.userData.morphs ? ratios[k] : 0)) morphing++;
    }
    stats.morphing_meshes = morphing;
    stats.meshes = this.#meshes.size;
    this.#stats = stats;
    this.#idleFrames = stats.idle ? this.#idleFrames + 1 : 0;
    const idle = this.#idleFrames >= 2;
    if (idle !== this.#idle) {
      this.#idle = idle;
      if (idle) this.dispatchEvent({ type: 'idle', stats });
    }
    this.dispatchEvent({ type: 'progress', stats });
    return stats;
  }

  // Draws `mesh` at morph ratio `r`; returns whether it morphs.
  #setRatio(mesh, r) {
    const u = mesh.userData;
    u.ratio = r;
    if (u.ownMaterial || u.custom) {
      const m = mesh.material.userData;
      if (m.tesseraRatio) {
        m.tesseraRatio.value = r;
        m.tesseraMinLod.value = r * (u.texelLod || 0);
      }
      return r > 0 && !!m.tesseraRatio;
    }
    // The shared material at rest; a morphing copy of it (made once) while r > 0.
    if (r > 0) {
      if (!u.morphMaterial) u.morphMaterial = morphMaterial(new THREE.MeshStandardMaterial(this.#sharedParams));
      u.morphMaterial.userData.tesseraRatio.value = r;
      mesh.material = u.morphMaterial;
      return true;
    }
    mesh.material = this.#shared;
    return false;
  }

  #material(patch) {
    if (this.#makeMaterial) {
      const m = this.#makeMaterial(patch);
      return { material: m, own: !m.userData.shared, custom: true };
    }
    if (patch.texture) {
      const t = new THREE.DataTexture(patch.texture, patch.width, patch.height, THREE.RGBAFormat, THREE.UnsignedByteType);
      t.colorSpace = THREE.SRGBColorSpace;
      t.flipY = false; // rows top to bottom, v down (as glTF)
      t.generateMipmaps = true;
      t.minFilter = THREE.LinearMipmapLinearFilter;
      t.magFilter = THREE.LinearFilter;
      t.wrapS = t.wrapT = THREE.ClampToEdgeWrapping;
      t.anisotropy = 4;
      t.needsUpdate = true;
      if (!this.#keepArrays) {
        t.onUpdate = () => {
          t.image.data = null;
        };
      }
      return { material: morphMaterial(new THREE.MeshStandardMaterial({ map: t, roughness: 0.85, metalness: 0 })), own: true };
    }
    if (!this.#shared) {
      const colors = patch.colors.length > 0;
      this.#sharedParams = { color: colors ? 0xffffff : CLAY, vertexColors: colors, roughness: 0.85, metalness: 0 };
      this.#shared = new THREE.MeshStandardMaterial(this.#sharedParams);
    }
    return { material: this.#shared, own: false };
  }

  #make(node, patch) {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(patch.positions, 3));
    if (patch.normals.length) g.setAttribute('normal', new THREE.BufferAttribute(patch.normals, 3));
    if (patch.colors.length) g.setAttribute('color', new THREE.BufferAttribute(patch.colors, 3));
    if (patch.uvs.length) g.setAttribute('uv', new THREE.BufferAttribute(patch.uvs, 2));
    g.setIndex(new THREE.BufferAttribute(patch.indices, 1));
    if (!patch.normals.length) g.computeVertexNormals();
    // The morph targets (a patch with moving vertices; see the top of the file). A
    // model without normals morphs the normals three.js computed.
    const morphs = patch.targets && patch.targets.length === patch.positions.length;
    if (morphs) {
      g.setAttribute('tesseraTarget', new THREE.BufferAttribute(patch.targets, 3));
      const tn = patch.targetNormals.length === patch.positions.length ? patch.targetNormals : g.attributes.normal.array;
      g.setAttribute('tesseraTargetNormal', new THREE.BufferAttribute(tn, 3));
      if (patch.colors.length) g.setAttribute('tesseraTargetColor', new THREE.BufferAttribute(patch.targetColors.length ? patch.targetColors : patch.colors, 3));
      if (patch.uvs.length) g.setAttribute('tesseraTargetUv', new THREE.BufferAttribute(patch.targetUvs.length ? patch.targetUvs : patch.uvs, 2));
    }
    g.computeBoundingSphere();
    if (!this.#keepArrays) {
      const drop = function () {
        this.array = null;
      };
      for (const a of Object.values(g.attributes)) a.onUpload(drop);
      g.index.onUpload(drop);
    }
    const { material, own, custom = false } = this.#material(patch);
    const mesh = new THREE.Mesh(g, material);
    mesh.name = `tessera node ${node}`;
    mesh.userData.node = node;
    mesh.userData.level = patch.level;
    mesh.userData.ownMaterial = own;
    mesh.userData.custom = custom;
    mesh.userData.morphs = morphs;
    mesh.userData.texelLod = patch.texelLod || 0;
    mesh.userData.ratio = 0;
    mesh.visible = false;
    mesh.matrixAutoUpdate = false;
    this.#content.add(mesh);
    this.#meshes.set(node, mesh);
  }

  #drop(node) {
    const mesh = this.#meshes.get(node);
    if (!mesh) return;
    this.#meshes.delete(node);
    this.#content.remove(mesh);
    mesh.geometry.dispose();
    if (mesh.userData.morphMaterial) mesh.userData.morphMaterial.dispose();
    if (mesh.userData.ownMaterial) {
      if (mesh.material.map) mesh.material.map.dispose();
      mesh.material.dispose();
    }
  }

  /** Stops streaming and frees every mesh, texture and material, the workers and the wasm side. */
  dispose() {
    if (this.#disposed) return;
    this.#disposed = true;
    for (const node of [...this.#meshes.keys()]) this.#drop(node);
    if (this.#shared) this.#shared.dispose();
    this.#shared = null;
    releasePool(this.#workers);
    this.#stream.close();
    this.#stream.free();
    this.removeFromParent();
    this.dispatchEvent({ type: 'dispose' });
  }
}

export default TesseraModel;
