// spectrageo viewer: two synchronised views (one canvas, two viewports, one camera) of the current
// model; the right one shows feature vertices, feature curves, heatmaps or a compared model.
import * as THREE from 'three';
import { OrbitControls } from '/static/vendor/OrbitControls.js';

const $ = (id) => document.getElementById(id);
const GREY = [190, 190, 190];
const RED = [255, 0, 0];
const CURVE_COLORS = [[228, 26, 28], [55, 126, 184], [77, 175, 74], [152, 78, 163], [255, 127, 0]];

// ------------------------------------------------------------------ API helpers
// Every API request carries the per-session token that the server wrote into index.html; the
// server refuses requests without it (and any cross-origin request). Names and other data are only
// ever inserted with textContent, never as HTML.
const TOKEN = (document.querySelector('meta[name="spectrageo-token"]') || {}).content || '';
function api(url, opts = {}) {
  const headers = new Headers(opts.headers || {});
  headers.set('X-Spectrageo-Token', TOKEN);
  return fetch(url, { ...opts, headers, credentials: 'same-origin', cache: 'no-store' });
}
function el(tag, text, attrs = {}) {
  const e = document.createElement(tag);
  if (text !== undefined) e.textContent = String(text);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  return e;
}
async function errorOf(r) {
  try { const j = await r.json(); return j.error || r.statusText; } catch { return r.statusText; }
}
async function getJSON(url, body) {
  const opts = body === undefined ? {} : {
    method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) };
  const r = await api(url, opts);
  if (!r.ok) throw new Error(await errorOf(r));
  return r.json();
}
const TYPES = { float32: Float32Array, uint32: Uint32Array, uint8: Uint8Array, int8: Int8Array,
  int32: Int32Array, float64: Float64Array };
async function getArray(url) {
  const r = await api(url);
  if (!r.ok) throw new Error(await errorOf(r));
  const T = TYPES[r.headers.get('X-Dtype')] || Uint8Array;
  return new T(await r.arrayBuffer());
}

// ------------------------------------------------------------------ status, jobs
const S = {
  models: [], info: null, faces: null, frames: new Map(), frame: 0, playing: false,
  features: null, curves: null, rightMode: 'features', heat: null, compare: null,
  busy: 0, renders: 0, pointSize: 2, mode: 'both', renderedFrame: -1,
};
window.__spectrageo = S;

function message(text, ok = false) {
  const m = $('message');
  m.textContent = text || '';
  m.className = ok ? 'ok' : '';
}
function busy(delta) {
  S.busy += delta;
  document.body.dataset.busy = S.busy > 0 ? '1' : '0';
}
async function runJob(url, body, label) {
  busy(+1);
  const bar = $('progress');
  bar.hidden = false; bar.removeAttribute('value');
  $('progress-text').textContent = label + '…';
  try {
    const { job } = await getJSON(url, body);
    for (;;) {
      const j = await getJSON('/api/job/' + job);
      if (j.progress === null) bar.removeAttribute('value'); else bar.value = j.progress;
      $('progress-text').textContent = `${j.message} (${j.elapsed.toFixed(1)} s)`;
      if (j.state === 'done') return j.result;
      if (j.state === 'error') throw new Error(j.error);
      await new Promise((res) => setTimeout(res, 100));
    }
  } finally {
    bar.hidden = true;
    busy(-1);
  }
}
async function guard(fn) {
  try { await fn(); } catch (e) {
    const text = String(e.message || e);
    message(text);
    if (/was unloaded/.test(text)) refreshState().catch(() => {});  // drop it from the lists
  }
}

// ------------------------------------------------------------------ rendering
// Rendering is on demand: requestRender() schedules one animation frame, nothing redraws otherwise.
// Level of detail: models above LOD.faces faces (LOD.points points) get a vertex-clustered proxy from
// the server (original vertices `reps`, faces into them); while the camera moves the proxy is drawn,
// and the full model once the motion has stopped for LOD.settleMs. Positions and colours of the
// proxy are gathered from the full model's attributes, so features/heatmaps/frames carry over.
const params = new URLSearchParams(window.location.search);
const LOD = {
  enabled: params.get('lod') !== '0',
  faces: Number(params.get('lod_faces')) || 150000,    // proxy for meshes with more faces
  points: Number(params.get('lod_points')) || 300000,  // ... and point clouds with more points
  budget: Number(params.get('lod_budget')) || 100000,  // proxy faces at most
  pointBudget: Number(params.get('lod_point_budget')) || 150000,
  settleMs: Number(params.get('lod_settle_ms')) || 250,
};
S.lod = null; S.interacting = false; S.detail = null;
S.rendersFull = 0; S.rendersProxy = 0; S.renderLog = [];
S.lodSettings = LOD;

// Multisampling costs a software rasteriser (SwiftShader, llvmpipe) about 3x per frame and a GPU
// almost nothing: it is on for GPUs only, unless the URL says `aa=1` or `aa=0`.
function rendererName() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2');
    if (!gl) return '';
    const ext = gl.getExtension('WEBGL_debug_renderer_info');
    const name = String(gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    const lose = gl.getExtension('WEBGL_lose_context');
    if (lose) lose.loseContext();
    return name;
  } catch { return ''; }
}
const GL_NAME = rendererName();
const SOFTWARE = /swiftshader|llvmpipe|softpipe|software/i.test(GL_NAME);
const ANTIALIAS = params.has('aa') ? params.get('aa') !== '0' : !SOFTWARE;
S.gl = { renderer: GL_NAME, software: SOFTWARE, antialias: ANTIALIAS };

const canvas = $('canvas');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: ANTIALIAS,
  preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
renderer.setScissorTest(true);
const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 100);
const controls = new OrbitControls(camera, canvas);
let settleTimer = null;
controls.addEventListener('start', () => {
  clearTimeout(settleTimer);
  S.interacting = true;
});
controls.addEventListener('change', () => requestRender());
controls.addEventListener('end', () => {
  clearTimeout(settleTimer);
  // wheel zooms send start/change/end at once: wait a moment before the (slow) full redraw
  settleTimer = setTimeout(() => { S.interacting = false; requestRender(); }, LOD.settleMs);
});

function makeLayer(scene) {
  const geometry = new THREE.BufferGeometry();
  const surface = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({ vertexColors: true,
    side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1 }));
  const points = new THREE.Points(geometry, new THREE.PointsMaterial({ vertexColors: true,
    size: 2, sizeAttenuation: false }));
  surface.frustumCulled = false; points.frustumCulled = false;
  scene.add(surface, points);
  return { geometry, surface, points };
}
function makeScene() {
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xffffff);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 1.6));
  const light = new THREE.DirectionalLight(0xffffff, 1.6);  // headlight, follows the camera
  scene.add(light, light.target);
  const full = makeLayer(scene), proxy = makeLayer(scene);
  return { scene, geometry: full.geometry, surface: full.surface, points: full.points, light,
    proxy };
}
const views = [makeScene(), makeScene()];
S.views = views;  // for tests and benchmarks

let scheduled = false;
function requestRender() {
  if (scheduled) return;
  scheduled = true;
  requestAnimationFrame(() => { scheduled = false; render(); });
}
window.addEventListener('resize', () => requestRender());
if (window.ResizeObserver) new ResizeObserver(() => requestRender()).observe(canvas);
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.floor(w * renderer.getPixelRatio()) ||
      canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = (w / 2) / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
}
function proxyReady() {
  return !!(LOD.enabled && S.lod && S.info && S.lod.modelId === S.info.id &&
    views[1].proxy.geometry.getAttribute('position'));
}
// Draws both viewports with one camera, so the panels always show the same view.
function render(detail) {
  resize();
  const useProxy = detail ? detail === 'proxy' : S.interacting && proxyReady();
  const w = canvas.clientWidth, h = canvas.clientHeight, half = Math.floor(w / 2);
  views.forEach((v, i) => {
    setVisibility(v, useProxy);
    v.light.position.copy(camera.position);
    v.light.target.position.copy(controls.target);
    renderer.setViewport(i * half, 0, half, h);
    renderer.setScissor(i * half, 0, half, h);
    renderer.render(v.scene, camera);
  });
  S.renders += 1;
  S.detail = useProxy ? 'proxy' : 'full';
  if (useProxy) S.rendersProxy += 1; else S.rendersFull += 1;
  S.renderLog.push([performance.now(), S.detail]);
  if (S.renderLog.length > 200) S.renderLog.splice(0, 100);
  S.renderedFrame = S.frame;
}
// Synchronous redraw timing (benchmarks): `n` redraws at a given detail, each waited for with a
// one-pixel read-back, mean milliseconds per redraw.
S.timeRender = (detail, n = 3) => {
  const gl = renderer.getContext(), px = new Uint8Array(4);
  render(detail); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  const t0 = performance.now();
  for (let k = 0; k < n; k++) {
    render(detail);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  }
  const ms = (performance.now() - t0) / n;
  requestRender();
  return ms;
};

function setVisibility(v, useProxy) {
  const hasFaces = !!(v.geometry.index && v.geometry.index.count);
  const surface = hasFaces && S.mode !== 'points';
  const points = !hasFaces || S.mode !== 'surface';
  v.surface.visible = !useProxy && surface;
  v.points.visible = !useProxy && points;
  const pHasFaces = !!(v.proxy.geometry.index && v.proxy.geometry.index.count);
  v.proxy.surface.visible = useProxy && surface && pHasFaces;
  v.proxy.points.visible = useProxy && (points || !pHasFaces);
}

// ---- the proxy: gathered from the full model's attributes at the representative vertices
function gather(dst, src, reps) {
  for (let i = 0, n = reps.length; i < n; i++) {
    const j = 3 * reps[i];
    dst[3 * i] = src[j]; dst[3 * i + 1] = src[j + 1]; dst[3 * i + 2] = src[j + 2];
  }
}
function syncProxyPositions(v) {
  const pg = v.proxy.geometry, pos = pg.getAttribute('position');
  const src = v.geometry.getAttribute('position');
  if (!S.lod || !pos || !src || src.count !== S.lod.nFull) return;
  gather(pos.array, src.array, S.lod.reps);
  pos.needsUpdate = true;
  if (pg.index && pg.index.count) pg.computeVertexNormals();
  pg.computeBoundingSphere();
}
function syncProxyColors(v) {
  const col = v.proxy.geometry.getAttribute('color');
  const src = v.geometry.getAttribute('color');
  if (!S.lod || !col || !src || src.count !== S.lod.nFull) return;
  gather(col.array, src.array, S.lod.reps);
  col.needsUpdate = true;
}
function clearProxy() {
  S.lod = null;
  for (const v of views) {
    const g = v.proxy.geometry;
    g.deleteAttribute('position'); g.deleteAttribute('color'); g.setIndex(null);
  }
  $('lod-info').hidden = true;
}
async function loadLod(info) {
  clearProxy();
  const big = info.n_faces ? info.n_faces > LOD.faces : info.n_vertices > LOD.points;
  if (!LOD.enabled || !big) return;
  const r = await getJSON(`/api/model/${info.id}/lod?max_faces=${LOD.budget}` +
    `&max_points=${LOD.pointBudget}`);
  const [reps, faces] = await Promise.all([
    getArray(`/api/model/${info.id}/array/${r.reps}`),
    getArray(`/api/model/${info.id}/array/${r.faces}`)]);
  if (!S.info || S.info.id !== info.id) return;  // another model was chosen meanwhile
  S.lod = { modelId: info.id, reps, faces, nFull: info.n_vertices, nVertices: r.n_vertices,
    nFaces: r.n_faces };
  for (const v of views) {
    const g = v.proxy.geometry, k = reps.length;
    g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * k), 3));
    g.setAttribute('color', new THREE.BufferAttribute(new Uint8Array(3 * k), 3, true));
    g.setIndex(faces.length ? new THREE.BufferAttribute(faces, 1) : null);
    syncProxyPositions(v);
    syncProxyColors(v);
  }
  const li = $('lod-info');
  li.textContent = `While moving: proxy of ${r.n_vertices.toLocaleString('en')} vertices` +
    (info.n_faces ? ` / ${r.n_faces.toLocaleString('en')} faces` : '') + ' (vertex clustering)';
  li.hidden = false;
}

function applyDisplay() {
  views.forEach((v) => {
    v.points.material.size = S.pointSize;
    v.proxy.points.material.size = S.pointSize;
  });
  requestRender();
}

function setGeometry(v, positions, faces) {
  const g = v.geometry;
  const n = positions.length / 3;
  const old = g.getAttribute('position');
  if (old && old.count === n && g.userData.faces === faces) {
    old.array.set(positions); old.needsUpdate = true;
  } else {
    g.setAttribute('position', new THREE.BufferAttribute(positions.slice(), 3));
    g.setAttribute('color', new THREE.BufferAttribute(new Uint8Array(n * 3), 3, true));
    g.setIndex(faces && faces.length ? new THREE.BufferAttribute(faces, 1) : null);
    g.userData.faces = faces;
  }
  if (faces && faces.length) g.computeVertexNormals();
  g.computeBoundingSphere();
  syncProxyPositions(v);
  requestRender();
}
function setColors(v, fn) {
  const c = v.geometry.getAttribute('color');
  if (!c) return;
  const a = c.array, n = c.count;
  for (let i = 0; i < n; i++) {
    const rgb = fn(i);
    a[3 * i] = rgb[0]; a[3 * i + 1] = rgb[1]; a[3 * i + 2] = rgb[2];
  }
  c.needsUpdate = true;
  syncProxyColors(v);
  requestRender();
}

function fitCamera(bbox) {
  resize();
  const lo = new THREE.Vector3(...bbox[0]), hi = new THREE.Vector3(...bbox[1]);
  const c = lo.clone().add(hi).multiplyScalar(0.5);
  const r = Math.max(hi.clone().sub(lo).length() / 2, 1e-9);
  controls.target.copy(c);
  camera.near = r / 100; camera.far = r * 100;
  const fovV = THREE.MathUtils.degToRad(camera.fov);
  const fovH = 2 * Math.atan(Math.tan(fovV / 2) * camera.aspect);
  const dist = (0.95 * r) / Math.sin(Math.min(fovV, fovH) / 2);
  camera.position.copy(c).add(new THREE.Vector3(0.6, 0.5, 1.0).normalize().multiplyScalar(dist));
  camera.updateProjectionMatrix();
  controls.update();
  requestRender();
}

// ------------------------------------------------------------------ model loading
async function positionsOf(info, frame) {
  const key = info.id + ':' + frame;
  if (!S.frames.has(key)) {
    S.frames.set(key, await getArray(`/api/model/${info.id}/positions?frame=${frame}`));
  }
  return S.frames.get(key);
}

async function selectModel(id) {
  const info = S.models.find((m) => m.id === id);
  if (!info) return;
  busy(+1);
  try {
    S.info = info; S.frame = 0; S.features = null; S.curves = null; S.heat = null;
    S.compare = null; S.rightMode = 'features'; S.playing = false;
    $('model-select').value = id;
    $('drop-hint').hidden = true;
    $('metrics-table').replaceChildren();
    S.faces = info.n_faces ? await getArray(`/api/model/${id}/faces`) : null;
    const pos = await positionsOf(info, 0);
    clearProxy();
    for (const v of views) setGeometry(v, pos, S.faces);
    fitCamera(info.bbox);
    const lod = loadLod(info);  // alongside the features job
    if (info.n_faces && info.n_vertices > 200000 && S.mode === 'both') {
      S.mode = 'surface';  // large meshes: points off by default (half the draw work)
      $('render-mode').value = 'surface';
    }
    applyDisplay();
    fillInfo();
    fillFieldList();
    fillDownloadFormats();
    const anim = info.n_frames > 1;
    $('anim-panel').hidden = !anim;
    $('frame-slider').max = String(info.n_frames - 1);
    $('frame-slider').value = '0';
    updateFrameLabel();
    $('play-btn').textContent = 'Play';
    recolor();
    await Promise.all([updateFeatures(), lod.then(() => requestRender())]);
  } finally {
    busy(-1);
  }
}

function fillInfo() {
  const i = S.info;
  $('info-name').textContent = i.name;
  $('info-vertices').textContent = String(i.n_vertices);
  $('info-faces').textContent = String(i.n_faces);
  $('info-features').textContent = S.features ? String(S.features.n_features) : '…';
  $('row-frames').hidden = i.n_frames <= 1;
  $('info-frames').textContent = String(i.n_frames);
  $('row-curves').hidden = !S.curves;
  $('info-curves').textContent = S.curves ? String(S.curves.n_curves) : '–';
  $('info-method').textContent = S.features ? 'features: ' + S.features.method : '';
}

function fillModelLists() {
  for (const sel of [$('model-select'), $('compare-select')]) {
    const keep = sel.value;
    sel.replaceChildren();
    for (const m of S.models) {
      const o = el('option', `${m.name} (${m.kind})`);
      o.value = m.id;
      sel.appendChild(o);
    }
    if (keep) sel.value = keep;
  }
}
function fillFieldList() {
  const sel = $('heat-field');
  sel.replaceChildren();
  for (const f of S.info.fields) {
    const o = document.createElement('option'); o.value = f; o.textContent = f; sel.appendChild(o);
  }
}
let FORMATS = null;
function fillDownloadFormats() {
  const sel = $('download-format');
  sel.replaceChildren();
  for (const f of (FORMATS && FORMATS.write[S.info.kind]) || []) {
    if (f.endsWith('/')) continue;
    const o = document.createElement('option'); o.value = f; o.textContent = f; sel.appendChild(o);
  }
}

async function refreshState() {
  const st = await getJSON('/api/state');
  S.models = st.models;
  S.limits = st.limits || null;
  FORMATS = st.formats;
  const dm = $('denoise-method');
  if (!dm.options.length) {
    for (const d of st.denoisers) {
      const o = document.createElement('option'); o.value = d.name; o.textContent = d.name;
      o.title = d.summary || ''; dm.appendChild(o);
    }
    for (const name of st.outlier_methods) {
      const o = document.createElement('option'); o.value = name; o.textContent = name;
      $('outlier-method').appendChild(o);
    }
    for (const name of st.hole_methods || []) {
      const o = document.createElement('option'); o.value = name; o.textContent = name;
      $('hole-method').appendChild(o);
    }
  }
  fillModelLists();
  return st;
}

function addModel(info) {
  if (!S.models.find((m) => m.id === info.id)) S.models.push(info);
  else S.models = S.models.map((m) => (m.id === info.id ? info : m));
  fillModelLists();
}

// ------------------------------------------------------------------ colouring of the right view
function recolor() {
  const left = views[0], right = views[1];
  setColors(left, () => GREY);
  const n = right.geometry.getAttribute('position') ? right.geometry.getAttribute('position').count : 0;
  $('colorbar').hidden = true;
  if ((S.rightMode === 'heat' || S.rightMode === 'compare') && S.heat && S.heat.colors.length === 3 * n) {
    const c = S.heat.colors;
    setColors(right, (i) => [c[3 * i], c[3 * i + 1], c[3 * i + 2]]);
    showColorbar(S.heat);
    $('caption-right').textContent = S.rightMode === 'compare'
      ? `${S.compare.name}: ${S.heat.label}` : S.heat.label;
  } else if (S.rightMode === 'curves' && S.curves && S.curves.labels.length === n) {
    const l = S.curves.labels;
    setColors(right, (i) => (l[i] < 0 ? GREY : CURVE_COLORS[l[i] % CURVE_COLORS.length]));
    $('caption-right').textContent = `Feature curves (${S.curves.n_curves})`;
  } else if (S.features && S.features.mask.length === n) {
    const m = S.features.mask;
    setColors(right, (i) => (m[i] ? RED : GREY));
    $('caption-right').textContent = `Features (red), patch ${S.features.patch}`;
  } else {
    setColors(right, () => GREY);
    $('caption-right').textContent = 'Features (red)';
  }
  $('caption-left').textContent = S.info ? `Original: ${S.info.name}` : 'Original';
}

function showColorbar(h) {
  const cv = $('cb-canvas'), ctx = cv.getContext('2d');
  h.colorbar.forEach((rgb, k) => {
    ctx.fillStyle = `rgb(${rgb[0]},${rgb[1]},${rgb[2]})`;
    ctx.fillRect(0, 63 - k, 16, 1);
  });
  $('cb-min').textContent = h.vmin.toPrecision(4);
  $('cb-max').textContent = h.vmax.toPrecision(4);
  $('cb-label').textContent = h.label;
  $('colorbar').hidden = false;
}

// ------------------------------------------------------------------ features / curves / heat
async function updateFeatures() {
  if (!S.info) return;
  const patch = Number($('patch-size').value);
  const r = await runJob(`/api/model/${S.info.id}/features`, { patch, frame: S.frame },
    `feature vertices (patch ${patch})`);
  r.mask = await getArray(`/api/model/${S.info.id}/array/${r.key}`);
  S.features = r;
  S.curves = null;
  if (S.rightMode !== 'heat' && S.rightMode !== 'compare') S.rightMode = 'features';
  fillInfo();
  recolor();
  if ($('show-curves').checked) await updateCurves();
}

async function updateCurves() {
  if (!S.info) return;
  const patch = Number($('patch-size').value);
  const r = await runJob(`/api/model/${S.info.id}/curves`, { patch, frame: S.frame },
    'feature curves');
  r.labels = await getArray(`/api/model/${S.info.id}/array/${r.key}`);
  S.curves = r;
  S.rightMode = 'curves';
  fillInfo();
  recolor();
}

async function loadHeat(result, modelId) {
  result.colors = await getArray(`/api/model/${modelId}/array/${result.colors}`);
  return result;
}

// ------------------------------------------------------------------ animation
function updateFrameLabel() {
  const l = $('frame-label');
  l.textContent = `${S.frame} / ${S.info ? S.info.n_frames - 1 : 0}`;
  l.dataset.frame = String(S.frame);
}
async function showFrame(t, stillWanted = () => true) {
  const pos = await positionsOf(S.info, t);
  if (!stillWanted()) return;
  S.frame = t;
  const faces = S.faces;
  setGeometry(views[0], pos, faces);
  if (S.rightMode !== 'compare') setGeometry(views[1], pos, faces);
  if (S.info.kind === 'sequence') recolor(); else requestRender();
  $('frame-slider').value = String(t);
  updateFrameLabel();
}
let playToken = 0;
async function play() {
  const token = ++playToken;
  const wanted = () => S.playing && token === playToken;
  const t0 = performance.now();
  let shown = 0;
  while (wanted() && S.info && S.info.n_frames > 1) {
    const t = (S.frame + 1) % S.info.n_frames;
    await showFrame(t, wanted);
    shown += 1;
    const due = t0 + shown * 40;  // 25 frames per second at most
    await new Promise((res) => setTimeout(res, Math.max(0, due - performance.now())));
  }
}

// ------------------------------------------------------------------ uploads
async function upload(file) {
  message('');
  busy(+1);
  try {
    $('progress-text').textContent = `uploading ${file.name}…`;
    const limit = S.limits && S.limits.max_upload_bytes;
    if (limit && file.size > limit) {
      throw new Error(`${file.name} is too large (${(file.size / 2 ** 20).toFixed(1)} MB; ` +
        `the viewer accepts up to ${(limit / 2 ** 20).toFixed(0)} MB, see --max-upload)`);
    }
    const r = await api('/api/upload?name=' + encodeURIComponent(file.name),
      { method: 'POST', body: file });
    if (!r.ok) throw new Error(await errorOf(r));
    const { model } = await r.json();
    addModel(model);
    $('progress-text').textContent = '';
    await selectModel(model.id);
    message(`loaded ${model.name}`, true);
  } finally {
    busy(-1);
  }
}

// ------------------------------------------------------------------ wiring
$('file-input').addEventListener('change', (e) => guard(async () => {
  const f = e.target.files[0];
  e.target.value = '';
  if (f) await upload(f);
}));
const main = $('views');
main.addEventListener('dragover', (e) => e.preventDefault());
main.addEventListener('drop', (e) => {
  e.preventDefault();
  const f = e.dataTransfer.files[0];
  if (f) guard(() => upload(f));
});
$('model-select').addEventListener('change', (e) => guard(() => selectModel(e.target.value)));
$('update-features').addEventListener('click', () => guard(async () => {
  message('');
  S.rightMode = 'features';
  await updateFeatures();
}));
$('show-curves').addEventListener('change', (e) => guard(async () => {
  if (e.target.checked) await updateCurves();
  else { S.curves = null; S.rightMode = 'features'; fillInfo(); recolor(); }
}));
$('point-size').addEventListener('input', (e) => {
  S.pointSize = Number(e.target.value);
  $('point-size-value').textContent = S.pointSize.toFixed(1);
  applyDisplay();
});
$('render-mode').addEventListener('change', (e) => { S.mode = e.target.value; applyDisplay(); });
$('frame-slider').addEventListener('input', (e) => guard(() => showFrame(Number(e.target.value))));
$('play-btn').addEventListener('click', () => {
  S.playing = !S.playing;
  if (!S.playing) playToken += 1;
  $('play-btn').textContent = S.playing ? 'Pause' : 'Play';
  if (S.playing) guard(play);
});
$('show-heat').addEventListener('click', () => guard(async () => {
  if (!S.info) return;
  message('');
  const field = $('heat-field').value;
  const r = await runJob(`/api/model/${S.info.id}/scalar`, { field, frame: S.frame }, field);
  S.heat = await loadHeat(r, S.info.id);
  S.rightMode = 'heat';
  recolor();
}));
$('field-input').addEventListener('change', (e) => guard(async () => {
  const f = e.target.files[0];
  e.target.value = '';
  if (!f || !S.info) return;
  const r = await api(`/api/field-upload?model=${S.info.id}&name=${encodeURIComponent(f.name)}`,
    { method: 'POST', body: f });
  if (!r.ok) throw new Error(await errorOf(r));
  const j = await r.json();
  addModel(j.model); S.info = j.model; fillFieldList();
  $('heat-field').value = j.field;
  message(`scalar field ${j.field} attached`, true);
}));
$('compare-btn').addEventListener('click', () => guard(async () => {
  if (!S.info) return;
  message('');
  const b = $('compare-select').value;
  const bInfo = S.models.find((m) => m.id === b);
  const r = await runJob('/api/compare', { a: S.info.id, b, frame: S.frame }, 'compare');
  S.heat = await loadHeat(r.heat, b);
  S.compare = bInfo;
  S.rightMode = 'compare';
  const pos = await positionsOf(bInfo, bInfo.n_frames > 1 ? S.frame : 0);
  setGeometry(views[1], pos, S.faces);
  recolor();
  const t = $('metrics-table');
  const head = el('tr');
  head.appendChild(el('th', `${bInfo.name} vs ${S.info.name}`, { colspan: 2 }));
  t.replaceChildren(head);
  for (const [k, v] of Object.entries(r.metrics)) {
    const tr = el('tr');
    tr.dataset.metric = k;
    tr.append(el('th', k), el('td', Number(v).toPrecision(5)));
    t.appendChild(tr);
  }
}));
async function processAndShow(url, body, label, after) {
  message('');
  const r = await runJob(url, body, label);
  addModel(r.model);
  await selectModel(r.model.id);
  if (after) after(r);
}
$('denoise-btn').addEventListener('click', () => guard(() => processAndShow(
  `/api/model/${S.info.id}/denoise`, { method: $('denoise-method').value },
  `denoising (${$('denoise-method').value})`,
  (r) => message(`denoised: ${r.model.name} (download it below)`, true))));
$('outlier-btn').addEventListener('click', () => guard(() => processAndShow(
  `/api/model/${S.info.id}/outliers`,
  { method: $('outlier-method').value, k: Number($('outlier-k').value) }, 'outlier removal',
  (r) => message(`removed ${r.n_removed} points: ${r.model.name}`, true))));
$('holes-btn').addEventListener('click', () => guard(() => processAndShow(
  `/api/model/${S.info.id}/fill-holes`, { method: $('hole-method').value }, 'hole filling',
  (r) => message(`closed ${r.n_loops} hole(s), ${r.n_implanted} vertices implanted: `
    + `${r.model.name}`, true))));
$('download-btn').addEventListener('click', () => guard(async () => {
  if (!S.info) return;
  const fmt = $('download-format').value;
  const r = await api(`/api/model/${S.info.id}/download?format=${encodeURIComponent(fmt)}`);
  if (!r.ok) throw new Error(await errorOf(r));
  const blob = await r.blob();
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = S.info.name.split('.')[0] + fmt;
  document.body.appendChild(a); a.click(); a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}));

// ------------------------------------------------------------------ start
guard(async () => {
  const st = await refreshState();
  if (st.models.length) await selectModel(st.models[0].id);
  document.body.dataset.ready = '1';
});
