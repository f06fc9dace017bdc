// lemi's web viewer: walks through an export (cells.json and one .glb per view cell, written by
// `lemi export` / `lemi serve`), streaming the cells ahead of the camera with the runtime's
// prediction rule (predict.js), drawing the current cell's near geometry and impostor quads.
//
// The cells are loaded with three.js's GLTFLoader as any engine would load them; the viewer then
// draws them as lemi's runtime does (crates/lemi-gpu/src/impostor/), so that its pictures match
// `lemi render BUNDLE`:
// - quads: the macro-texture's texels fetched unfiltered (texelFetch) and clamped to the quad's
//   texel rectangle (recovered from TEXCOORD_0), alpha test at the material's alphaCutoff, the
//   sRGB bytes written as they are; the files hold the quads as lemi draws them, grown by 1/16
//   texel on every side (lemi-core's QUAD_GROWTH_TEXELS) so that neighbouring quads overlap
//   instead of leaving pixel-wide cracks where edges meet;
// - near geometry: lemi's shading (crates/lemi-gpu/src/shading.wgsl): base colour × texture ×
//   vertex colour × (ambient 0.3 + sun 0.7 · |n·l|), l = normalize(1, 3, 2), in linear RGB,
//   encoded to sRGB.
// `?materials=gltf` shows the files' own materials as three.js interprets them instead.
//
// URL parameters: eye=x,y,z  dir=x,y,z (or yaw=, pitch= in degrees; yaw 0 looks along −Z, 90
// along +X)  fov=60 (vertical, degrees)  size=WxH (fixed canvas size)  hud=0  tint=1 (layers
// coloured)  transparent=1 (no page background behind the canvas)  walk=1 (walk the cells automatically, for the benchmark)  speed=5 (m/s).
// Keys: WASD move, Q/E down/up, shift faster, mouse drag (or pointer lock on click) looks,
// F fly/walk, L toggles the layer colouring, N the near geometry, H the HUD.
// window.lemi exposes the state for tests: ready, frame times, loaded cells, errors.

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
// the decoder of EXT_meshopt_compression, which `lemi export` compresses vertices and indices with
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';
// `lemi export --textures ktx2`: the bundle's BC7/BC1 blocks in KTX2 (Zstandard supercompressed),
// uploaded as they are where WebGL has the format; an ETC1S or UASTC bundle's Basis Universal
// KTX2 files are transcoded in the browser (to BC7 or BC3 here)
import { KTX2Loader } from 'three/addons/loaders/KTX2Loader.js';
import { predict, locate, cellId } from './predict.js';

// the files' texture coordinates are texel edges ± 1/16 texel (lemi-core's QUAD_GROWTH_TEXELS)
const TEXEL_GRID = 16;
// crates/lemi-walk/src/layer_tint.rs: colours of layers 0, 1, … (far to near), repeating
const PALETTE = [
  [230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
  [145, 30, 180], [70, 240, 240], [240, 50, 230], [210, 245, 60], [250, 190, 212],
];
const FACE_NAMES = ['+X', '-X', '+Y', '-Y', '+Z', '-Z'];

const params = new URLSearchParams(location.search);
const hud = document.getElementById('hud');
if (params.get('transparent') === '1') {
  // the page shows nothing behind the canvas: screenshots keep the canvas's alpha (coverage)
  document.documentElement.style.background = 'transparent';
  document.body.style.background = 'transparent';
}
// keep a resource timing entry for every cell a long walk fetches
if (performance.setResourceTimingBufferSize) performance.setResourceTimingBufferSize(100000);
const fetchedUrls = new Set();

const status = {
  ready: false, error: null, frames: 0, frameTimes: [], currentCell: null, shownCell: null,
  loadedCells: [], fetchedBytes: 0, residentBytes: 0, stalls: 0,
  // the formats the macro-textures were uploaded in: RGBA8 (PNG), BC1 or BC7 (KTX2 blocks)
  textureFormats: [],
};
// the cells' bytes as they came over the network (gzip-encoded by `lemi serve`), from the
// browser's resource timing (fetchedBytes counts them decoded); read when asked, since an entry
// may be filed a moment after its body was read
Object.defineProperty(status, 'transferredBytes', {
  enumerable: true,
  get() {
    let sum = 0;
    for (const url of fetchedUrls) {
      const entries = performance.getEntriesByName(url);
      const last = entries[entries.length - 1];
      sum += last && last.encodedBodySize ? last.encodedBodySize : 0;
    }
    return sum;
  },
});
window.lemi = status;

function numbers(name, n) {
  const s = params.get(name);
  if (s === null) return null;
  const v = s.split(',').map(Number);
  if (v.length !== n || !v.every(Number.isFinite)) throw new Error(`?${name}=${s}: expected ${n} numbers`);
  return v;
}

function fail(e) {
  status.error = String(e && e.message ? e.message : e);
  hud.classList.remove('hidden');
  hud.textContent = `error: ${status.error}`;
  console.error(e);
}

const QUAD_VERTEX = `
in vec3 position;
in vec2 texel;
in vec4 rect;
in float layer;
uniform mat4 modelViewMatrix;
uniform mat4 projectionMatrix;
out vec2 vTexel;
flat out vec4 vRect;
flat out int vLayer;
void main() {
  vTexel = texel;
  vRect = rect;
  vLayer = int(layer + 0.5);
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;

const QUAD_FRAGMENT = `
precision highp float;
precision highp int;
uniform highp sampler2D map;
uniform float cutoff;
uniform bool tint;
uniform vec3 palette[10];
in vec2 vTexel;
flat in vec4 vRect;
flat in int vLayer;
out vec4 outColor;
void main() {
  vec2 t = clamp(floor(vTexel), vRect.xy, vRect.zw - 1.0);
  vec4 c = texelFetch(map, ivec2(t), 0);
#ifndef OPAQUE
  if (c.a < cutoff) discard;
#endif
  vec3 rgb = c.rgb;
  if (tint) rgb = mix(rgb, palette[vLayer % 10], 0.6);
  outColor = vec4(rgb, 1.0);
}`;

const NEAR_VERTEX = `
in vec3 position;
in vec3 normal;
#ifdef HAS_UV
in vec2 uv;
out vec2 vUv;
#endif
#ifdef HAS_COLOR
in vec4 color;
out vec4 vColor;
#endif
uniform mat4 modelViewMatrix;
uniform mat4 projectionMatrix;
out vec3 vNormal;
void main() {
  vNormal = normal;
#ifdef HAS_UV
  vUv = uv;
#endif
#ifdef HAS_COLOR
  vColor = color;
#endif
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;

const NEAR_FRAGMENT = `
precision highp float;
uniform vec4 baseColor;
uniform vec3 lightDir;
uniform vec3 sun;
uniform vec3 ambient;
uniform bool grey;
#ifdef HAS_MAP
uniform sampler2D map;
#endif
in vec3 vNormal;
#ifdef HAS_UV
in vec2 vUv;
#endif
#ifdef HAS_COLOR
in vec4 vColor;
#endif
out vec4 outColor;
vec3 toSrgb(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}
void main() {
  vec4 albedo = baseColor;
#ifdef HAS_MAP
  albedo *= texture(map, vUv);
#endif
#ifdef HAS_COLOR
  albedo *= vColor;
#endif
  float len2 = dot(vNormal, vNormal);
  float ndl = len2 > 1e-20 ? abs(dot(vNormal * inversesqrt(len2), lightDir)) : 0.0;
  vec3 rgb = toSrgb(albedo.rgb * (ambient + sun * ndl));
  if (grey) rgb = vec3(dot(rgb, vec3(0.299, 0.587, 0.114)));
  outColor = vec4(rgb, 1.0);
}`;

const quadUniforms = { tint: { value: params.get('tint') === '1' } };
const nearUniforms = { grey: { value: quadUniforms.tint.value } };

/// Rebuilds one impostor primitive as lemi's runtime draws it: the quads' vertices as the file
/// holds them (grown), texel coordinates, the quad's texel rectangle and its layer per vertex.
// The WebGL extension each block format of a KTX2 texture needs (set in main()).
let glExtensions = null;
const BLOCK_EXTENSIONS = new Map([
  [THREE.RGBA_S3TC_DXT1_Format, ['BC1', 'WEBGL_compressed_texture_s3tc']],
  [THREE.RGB_S3TC_DXT1_Format, ['BC1', 'WEBGL_compressed_texture_s3tc']],
  [THREE.RGBA_BPTC_Format, ['BC7', 'EXT_texture_compression_bptc']],
  // what three.js transcodes Basis Universal (ETC1S, UASTC) to where BC7 is missing
  [THREE.RGBA_S3TC_DXT5_Format, ['BC3', 'WEBGL_compressed_texture_s3tc']],
]);

// A block-compressed macro-texture this browser cannot sample is a clear error, not a black cell.
function checkBlockFormat(map) {
  const noteFormat = (name) => {
    if (!status.textureFormats.includes(name)) status.textureFormats.push(name);
  };
  if (!map.isCompressedTexture) {
    noteFormat('RGBA8');
    return;
  }
  const need = BLOCK_EXTENSIONS.get(map.format);
  if (!need) throw new Error(`a KTX2 macro-texture of an unexpected format (three.js format ${map.format})`);
  if (glExtensions && !glExtensions.has(need[1])) {
    throw new Error(`the cells' ${need[0]} textures need WebGL's ${need[1]}, which this browser lacks: export with --textures png (lemi serve --textures png)`);
  }
  noteFormat(need[0]);
}

function lemiQuads(mesh, info) {
  const g = mesh.geometry;
  const map = mesh.material.map;
  checkBlockFormat(map);
  const w = map.image.width;
  const h = map.image.height;
  // TEXCOORD_0 is either f32 (t / side) or integers 16·t + 1 mapped by KHR_texture_transform,
  // which three's loader puts in the texture's repeat and offset: t = (uv·repeat + offset)·side
  const scale = [map.repeat.x * w, map.repeat.y * h];
  const shift = [map.offset.x * w, map.offset.y * h];
  const p = g.attributes.position.array;
  const uv = g.attributes.uv.array;
  const n = p.length / 12;
  const position = new Float32Array(p);
  const texel = new Float32Array(8 * n);
  const rect = new Float32Array(16 * n);
  const layer = new Float32Array(4 * n);
  const index = new Uint32Array(6 * n);
  const center = info.reference_viewpoint;
  // positions are relative to the mesh's node (translated to the reference viewpoint)
  const origin = new THREE.Vector3().setFromMatrixPosition(mesh.matrixWorld).toArray();
  for (let q = 0; q < n; q++) {
    const P = [0, 1, 2, 3].map((k) => [p[12 * q + 3 * k], p[12 * q + 3 * k + 1], p[12 * q + 3 * k + 2]]);
    // grown texel coordinates, exact on the 1/16-texel grid; the rectangle is their rounding
    const T = [0, 1, 2, 3].map((k) => [0, 1].map((i) =>
      Math.round((uv[8 * q + 2 * k + i] * scale[i] + shift[i]) * TEXEL_GRID) / TEXEL_GRID));
    const xs = T.map((t) => Math.round(t[0]));
    const ys = T.map((t) => Math.round(t[1]));
    const r = [Math.min(...xs), Math.min(...ys), Math.max(...xs), Math.max(...ys)];
    // the quad's layer: its face is the dominant axis of its centre seen from the reference
    // viewpoint, its layer the one at that distance
    const c = [0, 1, 2].map((i) => (P[0][i] + P[2][i]) / 2 + origin[i] - center[i]);
    const axis = [0, 1, 2].reduce((a, i) => (Math.abs(c[i]) > Math.abs(c[a]) ? i : a), 0);
    const face = FACE_NAMES[2 * axis + (c[axis] < 0 ? 1 : 0)];
    const distances = (info.layers[info.faces.indexOf(face)] || {}).distance || [];
    let best = 0;
    distances.forEach((d, k) => {
      if (Math.abs(d - Math.abs(c[axis])) < Math.abs(distances[best] - Math.abs(c[axis]))) best = k;
    });
    for (let k = 0; k < 4; k++) {
      texel.set(T[k], 8 * q + 2 * k);
      rect.set(r, 16 * q + 4 * k);
      layer[4 * q + k] = best;
    }
    index.set([0, 1, 2, 0, 2, 3].map((i) => 4 * q + i), 6 * q);
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(position, 3));
  geometry.setAttribute('texel', new THREE.BufferAttribute(texel, 2));
  geometry.setAttribute('rect', new THREE.BufferAttribute(rect, 4));
  geometry.setAttribute('layer', new THREE.BufferAttribute(layer, 1));
  geometry.setIndex(new THREE.BufferAttribute(index, 1));
  geometry.computeBoundingSphere();
  // the texels as stored (sRGB bytes), fetched without decoding (for KTX2 blocks: uploaded as
  // the UNORM variant of their sRGB format, so the sampled values are the stored ones)
  map.colorSpace = THREE.NoColorSpace;
  map.generateMipmaps = false;
  map.needsUpdate = true;
  const material = new THREE.RawShaderMaterial({
    glslVersion: THREE.GLSL3,
    vertexShader: QUAD_VERTEX,
    fragmentShader: QUAD_FRAGMENT,
    // quads whose texels all pass the alpha test are drawn without it (alphaMode OPAQUE), so
    // the depth test comes before shading
    defines: mesh.material.alphaTest > 0 ? {} : { OPAQUE: 1 },
    uniforms: {
      map: { value: map },
      cutoff: { value: mesh.material.alphaTest || 0.5 },
      tint: quadUniforms.tint,
      palette: { value: PALETTE.map((c) => new THREE.Vector3(c[0] / 255, c[1] / 255, c[2] / 255)) },
    },
    side: THREE.DoubleSide,
  });
  g.dispose();
  const m = new THREE.Mesh(geometry, material);
  m.renderOrder = 1; // after the near geometry, as the runtime draws
  m.frustumCulled = true;
  return m;
}

const SRGB_TO_LINEAR = Array.from({ length: 256 }, (_, i) => {
  const c = i / 255;
  return c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4;
});

function linearToSrgb(v) {
  v = Number.isNaN(v) ? 0 : Math.min(Math.max(v, 0), 1);
  const s = v <= 0.0031308 ? v * 12.92 : 1.055 * v ** (1 / 2.4) - 0.055;
  return Math.floor(s * 255 + 0.5);
}

const nearTextures = new WeakMap();

/// A scene texture with lemi's mip chain (crates/lemi-gpu/src/texture.rs: each level's texel the
/// average of the 2×2 texels it covers, colour in linear space, alpha linearly), so that the
/// filtered near geometry samples the levels lemi samples.
function lemiMipmapped(map) {
  if (nearTextures.has(map)) return nearTextures.get(map);
  const { width, height } = map.image;
  const canvas = new OffscreenCanvas(width, height);
  const ctx = canvas.getContext('2d', { colorSpace: 'srgb', willReadFrequently: true });
  ctx.drawImage(map.image, 0, 0);
  let level = { width, height, data: new Uint8Array(ctx.getImageData(0, 0, width, height).data.buffer) };
  const mipmaps = [level];
  while (level.width > 1 || level.height > 1) {
    const w = Math.max(level.width >> 1, 1);
    const h = Math.max(level.height >> 1, 1);
    const out = new Uint8Array(w * h * 4);
    for (let y = 0; y < h; y++) {
      for (let x = 0; x < w; x++) {
        const acc = [0, 0, 0, 0];
        for (const [dx, dy] of [[0, 0], [1, 0], [0, 1], [1, 1]]) {
          const sx = Math.min(2 * x + dx, level.width - 1);
          const sy = Math.min(2 * y + dy, level.height - 1);
          const i = (sy * level.width + sx) * 4;
          for (let c = 0; c < 3; c++) acc[c] += SRGB_TO_LINEAR[level.data[i + c]];
          acc[3] += level.data[i + 3];
        }
        const o = (y * w + x) * 4;
        for (let c = 0; c < 3; c++) out[o + c] = linearToSrgb(acc[c] / 4);
        out[o + 3] = Math.floor(acc[3] / 4 + 0.5);
      }
    }
    level = { width: w, height: h, data: out };
    mipmaps.push(level);
  }
  const t = new THREE.DataTexture(mipmaps[0].data, width, height, THREE.RGBAFormat);
  t.mipmaps = mipmaps;
  t.colorSpace = THREE.SRGBColorSpace;
  t.wrapS = map.wrapS;
  t.wrapT = map.wrapT;
  t.magFilter = THREE.LinearFilter;
  t.minFilter = THREE.LinearMipmapLinearFilter;
  t.generateMipmaps = false;
  t.flipY = false;
  t.needsUpdate = true;
  nearTextures.set(map, t);
  return t;
}

/// A near primitive with lemi's shading.
function lemiNear(mesh) {
  const src = mesh.material;
  const g = mesh.geometry;
  const defines = {};
  if (g.attributes.uv && src.map) defines.HAS_UV = 1;
  if (src.map) defines.HAS_MAP = 1;
  if (g.attributes.color) defines.HAS_COLOR = 1;
  if (g.attributes.color && g.attributes.color.itemSize === 3) {
    // three's loader keeps COLOR_0 as given; the shader reads four components
    const c = g.attributes.color;
    const rgba = new Float32Array(c.count * 4);
    for (let i = 0; i < c.count; i++) rgba.set([c.getX(i), c.getY(i), c.getZ(i), 1], 4 * i);
    g.setAttribute('color', new THREE.BufferAttribute(rgba, 4));
  }
  const l = new THREE.Vector3(1, 3, 2).normalize();
  const material = new THREE.RawShaderMaterial({
    glslVersion: THREE.GLSL3,
    vertexShader: NEAR_VERTEX,
    fragmentShader: NEAR_FRAGMENT,
    defines,
    uniforms: {
      // three keeps baseColorFactor linear in material.color and the alpha in opacity
      baseColor: { value: new THREE.Vector4(src.color.r, src.color.g, src.color.b, src.opacity) },
      map: { value: src.map ? lemiMipmapped(src.map) : null },
      lightDir: { value: l },
      sun: { value: new THREE.Vector3(0.7, 0.7, 0.7) },
      ambient: { value: new THREE.Vector3(0.3, 0.3, 0.3) },
      grey: nearUniforms.grey,
    },
    side: THREE.DoubleSide,
  });
  const m = new THREE.Mesh(g, material);
  m.renderOrder = 0;
  return m;
}

function inside(obj, name) {
  for (let o = obj; o; o = o.parent) if (o.name === name) return true;
  return false;
}

/// The cell's group to draw, from the loaded glTF.
function cellGroup(gltf) {
  const info = (gltf.scene.userData && gltf.scene.userData.lemi) || (gltf.scenes[0].userData || {}).lemi;
  if (!info) throw new Error('a .glb without lemi extras (not a lemi export)');
  if (params.get('materials') === 'gltf') return { group: gltf.scene, info, near: [], quads: [] };
  const group = new THREE.Group();
  const near = [];
  const quads = [];
  const meshes = [];
  gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
  for (const o of meshes) {
    o.updateWorldMatrix(true, false);
    let m;
    if (inside(o, 'impostors')) {
      m = lemiQuads(o, info);
      quads.push(m);
    } else {
      m = lemiNear(o);
      near.push(m);
    }
    m.matrixAutoUpdate = false;
    m.matrix.copy(o.matrixWorld);
    group.add(m);
  }
  return { group, info, near, quads };
}

async function main() {
  const index = await (await fetch('cells.json')).json();
  if (index.format !== 'lemi-gltf-export') throw new Error('cells.json is not a lemi export index');
  const grid = index.grid;
  const rule = index.prediction;
  const baked = new Map(index.cells.map((c) => [c.id, c]));
  if (baked.size === 0) throw new Error('cells.json lists no cells');

  const size = params.get('size');
  let width = window.innerWidth;
  let height = window.innerHeight;
  if (size) {
    [width, height] = size.split('x').map(Number);
  }
  const renderer = new THREE.WebGLRenderer({
    antialias: false,
    alpha: true,
    // screenshots capture the composited page, so the drawing buffer need not be kept
    preserveDrawingBuffer: params.get('preserve') === '1',
    reversedDepthBuffer: true,
    powerPreference: 'high-performance',
  });
  renderer.setPixelRatio(1);
  renderer.setSize(width, height);
  renderer.setClearColor(0x000000, 0);
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  document.body.appendChild(renderer.domElement);
  status.renderer = {
    reversedDepth: renderer.capabilities.reversedDepthBuffer === true,
    gl: renderer.getContext().getParameter(renderer.getContext().VERSION),
  };

  const fov = Number(params.get('fov') || 60);
  const camera = new THREE.PerspectiveCamera(fov, width / height, 0.05, 1e7);
  const first = index.cells[0];
  let eye = numbers('eye', 3) || first.center.slice();
  let yaw = 90; // along +X, as `lemi render BUNDLE` looks by default
  let pitch = 0;
  const dir = numbers('dir', 3);
  if (dir) {
    const l = Math.hypot(...dir);
    yaw = (Math.atan2(dir[0], -dir[2]) * 180) / Math.PI;
    pitch = (Math.asin(dir[1] / l) * 180) / Math.PI;
  }
  if (params.get('yaw') !== null) yaw = Number(params.get('yaw'));
  if (params.get('pitch') !== null) pitch = Number(params.get('pitch'));
  const exactDir = dir ? new THREE.Vector3(...dir).normalize() : null;

  const scene = new THREE.Scene();
  const loader = new GLTFLoader();
  loader.setMeshoptDecoder(MeshoptDecoder);
  glExtensions = renderer.extensions;
  // Basis Universal (ETC1S, UASTC) textures are transcoded by Binomial's transcoder, vendored
  loader.setKTX2Loader(
    new KTX2Loader().setTranscoderPath('./vendor/three/examples/jsm/libs/basis/').detectSupport(renderer));
  const cells = new Map(); // id → {state, group, bytes, info, lastWanted}
  let inFlight = 0;

  async function load(id) {
    const entry = baked.get(id);
    const cell = { state: 'loading', bytes: 0 };
    cells.set(id, cell);
    inFlight++;
    try {
      const response = await fetch(entry.file);
      if (!response.ok) throw new Error(`${entry.file}: HTTP ${response.status}`);
      const buffer = await response.arrayBuffer();
      cell.bytes = buffer.byteLength;
      status.fetchedBytes += buffer.byteLength;
      fetchedUrls.add(response.url);
      const gltf = await loader.parseAsync(buffer, '');
      Object.assign(cell, cellGroup(gltf));
      cell.group.visible = false;
      scene.add(cell.group);
      cell.state = 'ready';
    } catch (e) {
      cell.state = 'failed';
      fail(new Error(`cell ${id}: ${e.message || e}`));
    } finally {
      inFlight--;
    }
  }

  function evict(wanted) {
    const keep = Math.max(rule.max_cells, 1) + 4;
    const ready = [...cells.entries()].filter(([, c]) => c.state === 'ready');
    if (ready.length <= keep) return;
    ready.sort((a, b) => (a[1].lastWanted || 0) - (b[1].lastWanted || 0));
    for (const [id, c] of ready.slice(0, ready.length - keep)) {
      if (wanted.has(id) || id === status.shownCell) continue;
      scene.remove(c.group);
      c.group.traverse((o) => {
        if (o.geometry) o.geometry.dispose();
        if (o.material) {
          if (o.material.uniforms && o.material.uniforms.map && o.material.uniforms.map.value) o.material.uniforms.map.value.dispose();
          o.material.dispose();
        }
      });
      cells.delete(id);
    }
  }

  // input
  const held = new Set();
  let tint = quadUniforms.tint.value;
  // fly (W follows the pitch, Q/E down/up) or walk (horizontal at the eye height walking was
  // switched on at), as `lemi view`
  let walking = false;
  let walkHeight = eye[1];
  let showNear = params.get('near') !== '0';
  let showHud = params.get('hud') !== '0';
  hud.classList.toggle('hidden', !showHud);
  addEventListener('keydown', (e) => {
    held.add(e.code);
    if (e.code === 'KeyL') { tint = !tint; quadUniforms.tint.value = tint; nearUniforms.grey.value = tint; }
    if (e.code === 'KeyN') showNear = !showNear;
    if (e.code === 'KeyH') { showHud = !showHud; hud.classList.toggle('hidden', !showHud); }
    if (e.code === 'KeyF') { walking = !walking; walkHeight = eye[1]; }
  });
  addEventListener('keyup', (e) => held.delete(e.code));
  let dragging = false;
  renderer.domElement.addEventListener('mousedown', () => { dragging = true; });
  addEventListener('mouseup', () => { dragging = false; });
  renderer.domElement.addEventListener('click', () => { if (renderer.domElement.requestPointerLock) renderer.domElement.requestPointerLock(); });
  addEventListener('mousemove', (e) => {
    if (!dragging && document.pointerLockElement !== renderer.domElement) return;
    yaw += e.movementX * 0.15;
    pitch = Math.max(-89, Math.min(89, pitch - e.movementY * 0.15));
  });
  if (!size) {
    addEventListener('resize', () => {
      width = window.innerWidth; height = window.innerHeight;
      renderer.setSize(width, height);
      camera.aspect = width / height;
      camera.updateProjectionMatrix();
    });
  }

  // the automatic walk (benchmark): back and forth through the centres of the baked cells
  const walk = params.get('walk') === '1';
  const path = index.cells.map((c) => c.center).sort((a, b) => a[0] - b[0] || a[2] - b[2]);
  let walkT = 0;
  const speed = Number(params.get('speed') || 5);
  function walkPose(dt) {
    if (path.length < 2) return;
    const legs = [];
    let total = 0;
    for (let i = 0; i + 1 < path.length; i++) {
      const l = Math.hypot(...[0, 1, 2].map((k) => path[i + 1][k] - path[i][k]));
      legs.push(l); total += l;
    }
    walkT = (walkT + speed * dt) % (2 * total);
    let s = walkT <= total ? walkT : 2 * total - walkT;
    const forward = walkT <= total;
    for (let i = 0; i < legs.length; i++) {
      if (s <= legs[i] || i === legs.length - 1) {
        const f = legs[i] > 0 ? Math.min(s / legs[i], 1) : 0;
        eye = [0, 1, 2].map((k) => path[i][k] + f * (path[i + 1][k] - path[i][k]));
        const d = [0, 1, 2].map((k) => (path[i + 1][k] - path[i][k]) * (forward ? 1 : -1));
        yaw = (Math.atan2(d[0], -d[2]) * 180) / Math.PI;
        pitch = 0;
        return;
      }
      s -= legs[i];
    }
  }

  let last = performance.now();
  let lastEye = eye.slice();
  let velocity = [0, 0, 0];
  let fpsFrames = 0;
  let fpsStart = last;
  let fps = 0;
  let tick = 0;
  let hudUpdated = 0;

  function frame(now) {
    // the frame timer: every frame's time as measured; movement steps at most 0.25 s
    const elapsed = now - last;
    const dt = Math.min(elapsed / 1000, 0.25);
    last = now;
    status.frames++;
    if (status.frames > 1) status.frameTimes.push(elapsed);
    if (status.frameTimes.length > 100000) status.frameTimes.splice(0, 50000);
    fpsFrames++;
    if (now - fpsStart >= 1000) { fps = (1000 * fpsFrames) / (now - fpsStart); fpsFrames = 0; fpsStart = now; }

    // movement
    if (walk) walkPose(dt);
    else {
      const fast = held.has('ShiftLeft') || held.has('ShiftRight') ? 4 : 1;
      const v = speed * fast * dt;
      const y = (yaw * Math.PI) / 180;
      const p = (pitch * Math.PI) / 180;
      const fwd = walking
        ? [Math.sin(y), 0, -Math.cos(y)]
        : [Math.sin(y) * Math.cos(p), Math.sin(p), -Math.cos(y) * Math.cos(p)];
      const right = [Math.cos(y), 0, Math.sin(y)];
      const move = (d, s) => { eye = [0, 1, 2].map((k) => eye[k] + d[k] * s); };
      if (held.has('KeyW')) move(fwd, v);
      if (held.has('KeyS')) move(fwd, -v);
      if (held.has('KeyD')) move(right, v);
      if (held.has('KeyA')) move(right, -v);
      if (!walking && held.has('KeyE')) move([0, 1, 0], v);
      if (!walking && held.has('KeyQ')) move([0, 1, 0], -v);
      if (walking) eye[1] = walkHeight;
      if (held.has('ArrowLeft')) yaw -= 90 * dt;
      if (held.has('ArrowRight')) yaw += 90 * dt;
      if (held.has('ArrowUp')) pitch = Math.min(89, pitch + 90 * dt);
      if (held.has('ArrowDown')) pitch = Math.max(-89, pitch - 90 * dt);
    }
    if (dt > 0) {
      const v = [0, 1, 2].map((k) => (eye[k] - lastEye[k]) / dt);
      velocity = [0, 1, 2].map((k) => 0.8 * velocity[k] + 0.2 * v[k]);
    }
    lastEye = eye.slice();

    // streaming: the runtime's prediction, the current cell first
    tick++;
    const wanted = predict(eye, velocity, grid, rule).filter((p) => baked.has(p.id));
    const wantedIds = new Set(wanted.map((p) => p.id));
    for (const p of wanted) {
      const c = cells.get(p.id);
      if (c) c.lastWanted = tick;
      else if (inFlight < 2) load(p.id);
    }
    evict(wantedIds);
    const here = locate(grid, eye);
    const hereId = here ? cellId(here) : null;
    status.currentCell = hereId;
    const current = hereId && cells.get(hereId);
    if (current && current.state === 'ready') status.shownCell = hereId;
    else if (hereId && baked.has(hereId)) status.stalls++;
    for (const [id, c] of cells) {
      if (c.state !== 'ready') continue;
      c.group.visible = id === status.shownCell;
      for (const m of c.near) m.visible = showNear;
    }

    // camera
    camera.position.set(...eye);
    if (exactDir && !walk && held.size === 0 && !dragging && status.frames < 2) {
      camera.up.set(0, 1, 0);
      camera.lookAt(eye[0] + exactDir.x, eye[1] + exactDir.y, eye[2] + exactDir.z);
    } else {
      const y = (yaw * Math.PI) / 180;
      const p = (pitch * Math.PI) / 180;
      camera.lookAt(eye[0] + Math.sin(y) * Math.cos(p), eye[1] + Math.sin(p), eye[2] - Math.cos(y) * Math.cos(p));
    }
    renderer.render(scene, camera);

    const shown = status.shownCell && cells.get(status.shownCell);
    status.loadedCells = [...cells.entries()].filter(([, c]) => c.state === 'ready').map(([id]) => id);
    status.residentBytes = [...cells.values()].reduce((s, c) => s + (c.state === 'ready' ? c.bytes : 0), 0);
    if (shown && shown.state === 'ready' && hereId === status.shownCell) {
      status.readyFrames = (status.readyFrames || 0) + 1;
      // two frames after the current cell is shown: its textures are uploaded and drawn
      if (status.readyFrames >= 2) status.ready = true;
    }
    if (showHud && now - hudUpdated >= 250) {
      // four times a second: rewriting the text re-lays out the page
      hudUpdated = now;
      hud.textContent = [
        `fps      ${fps.toFixed(1)}`,
        `cell     ${hereId || 'outside the grid'}${shown && hereId !== status.shownCell ? ` (showing ${status.shownCell}, loading)` : ''}`,
        `eye      ${eye.map((v) => v.toFixed(2)).join(', ')}`,
        `loaded   ${status.loadedCells.length} cells: ${status.loadedCells.join(' ')}`,
        `bytes    ${(status.residentBytes / 1e6).toFixed(2)} MB resident, ${(status.fetchedBytes / 1e6).toFixed(2)} MB fetched (${(status.transferredBytes / 1e6).toFixed(2)} MB sent)`,
        shown && shown.info ? `quads    ${shown.info.quads}, near triangles ${shown.info.near_triangles}, layers ${shown.info.layer_count.join('/')}` : '',
        `keys     WASD QE move, drag/click to look, F ${walking ? 'walk (on)' : 'fly'}, L layers${tint ? ' (on)' : ''}, N near${showNear ? '' : ' (off)'}, H HUD`,
      ].join('\n');
    }
    requestAnimationFrame(frame);
  }
  requestAnimationFrame(frame);
}

main().catch(fail);
