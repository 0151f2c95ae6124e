// scode viewer: decodes a .scode file in WebAssembly (../wasm, built into ./pkg by
// build.sh), refines its control mesh once to the finest level within a triangle budget, and
// shows it with WebGL2. In "auto" mode every base triangle gets the level at which its
// projected edges are about `pixels per edge` long (S-CODE section 4); the engine fills the
// gaps between levels so the surface stays crack-free. Levels are re-chosen as the camera moves.
//
// URL parameters: ?file=URL (load a file), &budget=N (finest-level triangle budget, default
// 2^21), &target=PX (pixels per edge). window.scodeViewer exposes state and hooks for tests.

import init, { ScodeModel } from './pkg/scode_wasm.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const BUDGET = Number(params.get('budget')) || (1 << 21);

// ---------------------------------------------------------------- small matrix helpers
// Column-major 4x4 matrices in Float32Array(16), as WebGL expects.
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
  return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
}
function lookAt(eye, at, up) {
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => { const l = Math.hypot(...a) || 1; return a.map((x) => x / l); };
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
  return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
    -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
}
function mul(a, b) {
  const o = new Float32Array(16);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
    let s = 0;
    for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
    o[c * 4 + r] = s;
  }
  return o;
}

// ---------------------------------------------------------------- WebGL setup
const canvas = $('canvas');
const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });

const SURFACE_VS = `#version 300 es
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_nrm;
layout(location = 2) in uint a_group;
uniform mat4 u_mvp;
uniform bool u_groups;
out vec3 v_nrm; out vec3 v_pos; out vec3 v_color;
vec3 hsv(float h, float s, float v) {
  vec3 k = clamp(abs(mod(h * 6.0 + vec3(0.0, 4.0, 2.0), 6.0) - 3.0) - 1.0, 0.0, 1.0);
  return v * mix(vec3(1.0), k, s);
}
void main() {
  gl_Position = u_mvp * vec4(a_pos, 1.0);
  v_nrm = a_nrm; v_pos = a_pos;
  v_color = u_groups ? hsv(fract(float(a_group) * 0.618034 + 0.1), 0.42, 0.93) : vec3(0.74, 0.77, 0.82);
}`;
const SURFACE_FS = `#version 300 es
precision highp float;
in vec3 v_nrm; in vec3 v_pos; in vec3 v_color;
uniform vec3 u_eye;
out vec4 color;
void main() {
  vec3 n = normalize(v_nrm);
  vec3 v = normalize(u_eye - v_pos);
  float d = dot(n, v);
  if (d < 0.0) { n = -n; d = -d; }
  // headlight plus a fixed key light from above
  vec3 key = normalize(vec3(0.3, 1.0, 0.5));
  float diff = 0.65 * d + 0.25 * max(dot(n, key), 0.0);
  float spec = pow(max(d, 0.0), 48.0) * 0.18;
  color = vec4(v_color * (0.22 + diff) + vec3(spec), 1.0);
}`;
const LINE_VS = `#version 300 es
layout(location = 0) in vec3 a_pos;
uniform mat4 u_mvp;
void main() { gl_Position = u_mvp * vec4(a_pos, 1.0); }`;
const LINE_FS = `#version 300 es
precision highp float;
uniform vec4 u_color;
out vec4 color;
void main() { color = u_color; }`;

function program(vs, fs) {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
}

let surfaceProgram, lineProgram;
const buffers = {};
function setupGL() {
  surfaceProgram = program(SURFACE_VS, SURFACE_FS);
  lineProgram = program(LINE_VS, LINE_FS);
  buffers.surfaceVao = gl.createVertexArray();
  buffers.lineVao = gl.createVertexArray();
  buffers.wireVao = gl.createVertexArray();
  for (const name of ['pos', 'nrm', 'grp', 'idx', 'line', 'wire']) buffers[name] = gl.createBuffer();
  gl.bindVertexArray(buffers.surfaceVao);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.pos);
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.nrm);
  gl.enableVertexAttribArray(1);
  gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 0, 0);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.grp);
  gl.enableVertexAttribArray(2);
  gl.vertexAttribIPointer(2, 1, gl.UNSIGNED_INT, 0, 0);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.idx);
  gl.bindVertexArray(buffers.lineVao);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.line);
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(buffers.wireVao);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.pos);
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.wire);
  gl.bindVertexArray(null);
  gl.enable(gl.DEPTH_TEST);
}

// ---------------------------------------------------------------- state
const state = {
  name: '', fileBytes: 0, model: null, levels: null, lod: 'auto',
  target: Number(params.get('target')) || 8,
  camera: { target: [0, 0, 0], radius: 1, dist: 3, yaw: 0.7, pitch: 0.45 },
  counts: { triangles: 0, vertices: 0, lineVertices: 0, wireIndices: 0, indices: 0 },
  timings: { decodeMs: 0, refineMs: 0, extractMs: 0, uploadMs: 0 },
  levelStats: { min: 0, max: 0, mean: 0 },
  extractions: 0, frames: 0, lastExtract: 0, pending: null, wireStale: true, error: '',
};

function showError(e) {
  state.error = String(e && e.message ? e.message : e);
  $('error').textContent = state.error;
  console.error(e);
}

function fmt(n, digits = 0) {
  return Number(n).toLocaleString('en-US', { maximumFractionDigits: digits, minimumFractionDigits: digits });
}

function updateInfo() {
  const m = state.model;
  const rows = [];
  if (m) {
    rows.push(['file', state.name]);
    rows.push(['file size', `${fmt(state.fileBytes)} B`]);
    rows.push(['control mesh', `${fmt(m.vertexCount)} V, ${fmt(m.faceCount)} F`]);
    rows.push(['CAD faces (groups)', fmt(m.groupCount)]);
    rows.push(['base triangles', fmt(m.baseTriangleCount)]);
    rows.push(['finest level', `${m.maxLevel} (${fmt(m.baseTriangleCount * 4 ** m.maxLevel)} tri)`]);
    rows.push(['triangles drawn', fmt(state.counts.triangles)]);
    const ls = state.levelStats;
    rows.push(['levels min/mean/max', `${ls.min} / ${fmt(ls.mean, 2)} / ${ls.max}`]);
    rows.push(['decode', `${fmt(state.timings.decodeMs, 1)} ms`]);
    rows.push(['refine', `${fmt(state.timings.refineMs, 1)} ms`]);
    rows.push(['extract + upload', `${fmt(state.timings.extractMs, 1)} + ${fmt(state.timings.uploadMs, 1)} ms`]);
  }
  $('info').innerHTML = rows.map(([k, v]) => `<tr><td>${k}</td><td>${String(v).replace(/</g, '&lt;')}</td></tr>`).join('');
}

// ---------------------------------------------------------------- camera
function matrices() {
  const w = canvas.width, h = canvas.height, c = state.camera;
  const dir = [Math.cos(c.pitch) * Math.sin(c.yaw), Math.sin(c.pitch), Math.cos(c.pitch) * Math.cos(c.yaw)];
  const eye = c.target.map((t, i) => t + dir[i] * c.dist);
  const near = Math.max(c.dist - 2 * c.radius, c.dist * 0.002, c.radius * 1e-4);
  const far = c.dist + 2 * c.radius;
  const view = lookAt(eye, c.target, [0, 1, 0]);
  const proj = perspective(Math.PI / 4, w / Math.max(h, 1), near, far);
  return { mvp: mul(proj, view), eye, view };
}

function resetCamera() {
  if (!state.model) return;
  const b = state.model.bounds();
  const c = state.camera;
  c.target = [(b[0] + b[3]) / 2, (b[1] + b[4]) / 2, (b[2] + b[5]) / 2];
  c.radius = Math.max(Math.hypot(b[3] - b[0], b[4] - b[1], b[5] - b[2]) / 2, 1e-9);
  c.dist = c.radius / Math.sin(Math.PI / 8) * 1.05;
  c.yaw = 0.7; c.pitch = 0.45;
  requestRender();
}

// ---------------------------------------------------------------- mesh upload
function upload(mesh) {
  const t0 = performance.now();
  const positions = mesh.takePositions(), normals = mesh.takeNormals();
  const indices = mesh.takeIndices(), groups = mesh.takeGroups(), lines = mesh.takeLines();
  const t1 = performance.now();
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.pos);
  gl.bufferData(gl.ARRAY_BUFFER, positions, gl.DYNAMIC_DRAW);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.nrm);
  gl.bufferData(gl.ARRAY_BUFFER, normals, gl.DYNAMIC_DRAW);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.grp);
  gl.bufferData(gl.ARRAY_BUFFER, groups, gl.DYNAMIC_DRAW);
  gl.bindVertexArray(buffers.surfaceVao);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.idx);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.DYNAMIC_DRAW);
  gl.bindVertexArray(null);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.line);
  gl.bufferData(gl.ARRAY_BUFFER, lines, gl.DYNAMIC_DRAW);
  state.counts = {
    triangles: mesh.triangleCount, vertices: mesh.vertexCount, indices: indices.length,
    lineVertices: lines.length / 3, wireIndices: 0,
  };
  state.lastIndices = indices;
  state.wireStale = true;
  mesh.free();
  return { takeMs: t1 - t0, uploadMs: performance.now() - t1 };
}

function uploadWire() {
  const idx = state.lastIndices;
  if (!idx) return;
  const wire = new Uint32Array(idx.length * 2);
  for (let t = 0; t < idx.length; t += 3) {
    const o = t * 2;
    wire[o] = idx[t]; wire[o + 1] = idx[t + 1];
    wire[o + 2] = idx[t + 1]; wire[o + 3] = idx[t + 2];
    wire[o + 4] = idx[t + 2]; wire[o + 5] = idx[t];
  }
  gl.bindVertexArray(buffers.wireVao);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.wire);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, wire, gl.DYNAMIC_DRAW);
  gl.bindVertexArray(null);
  state.counts.wireIndices = wire.length;
  state.wireStale = false;
}

function setLevelStats(levels) {
  let min = 255, max = 0, sum = 0;
  for (const l of levels) { if (l < min) min = l; if (l > max) max = l; sum += l; }
  state.levelStats = { min: levels.length ? min : 0, max, mean: levels.length ? sum / levels.length : 0 };
}

function extract(levels) {
  const t0 = performance.now();
  const mesh = state.model.extractLevels(levels);
  const t1 = performance.now();
  const u = upload(mesh);
  state.timings.extractMs = t1 - t0 + u.takeMs;
  state.timings.uploadMs = u.uploadMs;
  state.levels = levels;
  setLevelStats(levels);
  state.extractions++;
  state.lastExtract = performance.now();
}

function sameLevels(a, b) {
  if (!a || !b || a.length !== b.length) return false;
  for (let i = 0; i < a.length; i++) if (a[i] !== b[i]) return false;
  return true;
}

// ---------------------------------------------------------------- rendering
let renderQueued = false;
function requestRender() {
  if (!renderQueued) { renderQueued = true; requestAnimationFrame(render); }
}

function resize() {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
}

function chooseLevels(mvp) {
  const m = state.model;
  if (state.lod === 'auto') return m.viewLevels(mvp, canvas.width, canvas.height, state.target);
  return new Uint8Array(m.baseTriangleCount).fill(Number(state.lod));
}

function render() {
  renderQueued = false;
  resize();
  gl.viewport(0, 0, canvas.width, canvas.height);
  gl.clearColor(0.914, 0.929, 0.949, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  if (!state.model) return;
  const { mvp, eye } = matrices();
  try {
    const levels = chooseLevels(mvp);
    if (!sameLevels(levels, state.levels)) {
      // Re-extract at most every 100 ms while the camera moves; catch up when it stops.
      const since = performance.now() - state.lastExtract;
      if (since >= 100 || !state.levels) {
        extract(levels);
      } else {
        clearTimeout(state.pending);
        state.pending = setTimeout(requestRender, 100 - since);
      }
    }
  } catch (e) { showError(e); }
  gl.useProgram(surfaceProgram);
  gl.uniformMatrix4fv(gl.getUniformLocation(surfaceProgram, 'u_mvp'), false, mvp);
  gl.uniform3fv(gl.getUniformLocation(surfaceProgram, 'u_eye'), eye);
  gl.uniform1i(gl.getUniformLocation(surfaceProgram, 'u_groups'), $('groups').checked ? 1 : 0);
  gl.enable(gl.POLYGON_OFFSET_FILL);
  gl.polygonOffset(1, 1);
  gl.bindVertexArray(buffers.surfaceVao);
  gl.drawElements(gl.TRIANGLES, state.counts.indices, gl.UNSIGNED_INT, 0);
  gl.disable(gl.POLYGON_OFFSET_FILL);
  gl.useProgram(lineProgram);
  gl.uniformMatrix4fv(gl.getUniformLocation(lineProgram, 'u_mvp'), false, mvp);
  if ($('wire').checked) {
    if (state.wireStale) uploadWire();
    gl.uniform4fv(gl.getUniformLocation(lineProgram, 'u_color'), [0.25, 0.3, 0.4, 1]);
    gl.bindVertexArray(buffers.wireVao);
    gl.drawElements(gl.LINES, state.counts.wireIndices, gl.UNSIGNED_INT, 0);
  }
  if ($('edges').checked) {
    gl.uniform4fv(gl.getUniformLocation(lineProgram, 'u_color'), [0.05, 0.06, 0.1, 1]);
    gl.bindVertexArray(buffers.lineVao);
    gl.drawArrays(gl.LINES, 0, state.counts.lineVertices);
  }
  gl.bindVertexArray(null);
  state.frames++;
  updateInfo();
}

// ---------------------------------------------------------------- loading
function loadBytes(bytes, name) {
  state.error = '';
  $('error').textContent = '';
  if (state.model) { state.model.free(); state.model = null; }
  state.levels = null;
  state.lastIndices = null;
  const t0 = performance.now();
  const model = new ScodeModel(bytes);
  const t1 = performance.now();
  model.refine(model.levelForBudget(BUDGET));
  const t2 = performance.now();
  state.model = model;
  state.name = name;
  state.fileBytes = bytes.length;
  state.timings.decodeMs = t1 - t0;
  state.timings.refineMs = t2 - t1;
  const sel = $('lod');
  sel.innerHTML = '<option value="auto">auto (screen size)</option>' +
    Array.from({ length: model.maxLevel + 1 }, (_, l) => `<option value="${l}">uniform ${l}</option>`).join('');
  sel.value = state.lod = 'auto';
  resetCamera();
  render();
}

async function loadUrl(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  const bytes = new Uint8Array(await r.arrayBuffer());
  loadBytes(bytes, decodeURIComponent(url.split('/').pop() || url));
}

async function loadFile(file) {
  const bytes = new Uint8Array(await file.arrayBuffer());
  loadBytes(bytes, file.name);
}

/// Decode + refine to the uniform level whose triangle count is nearest `triangles` (each
/// level is 4x the previous one, so within a factor 2) + extraction of WebGL-ready arrays,
/// timed (used by the end-to-end test; does not touch the view).
function benchmark(bytes, triangles) {
  const t0 = performance.now();
  const m = new ScodeModel(bytes);
  const t1 = performance.now();
  const level = Math.max(0, Math.round(Math.log(triangles / Math.max(1, m.baseTriangleCount)) / Math.log(4)));
  m.refine(level);
  const t2 = performance.now();
  const mesh = m.extractUniform(level);
  const arrays = [mesh.takePositions(), mesh.takeNormals(), mesh.takeIndices(), mesh.takeGroups(), mesh.takeLines()];
  const t3 = performance.now();
  const result = {
    level, triangles: mesh.triangleCount, vertices: mesh.vertexCount,
    bytes: arrays.reduce((s, a) => s + a.byteLength, 0),
    decodeMs: t1 - t0, refineMs: t2 - t1, extractMs: t3 - t2, totalMs: t3 - t0,
  };
  mesh.free();
  m.free();
  return result;
}

// ---------------------------------------------------------------- input
function setupInput() {
  let drag = null;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('pointerdown', (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 || e.button === 1 };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener('pointerup', () => { drag = null; });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    const c = state.camera;
    if (drag.pan) {
      const { view } = matrices();
      const s = c.dist * 2 * Math.tan(Math.PI / 8) / Math.max(canvas.clientHeight, 1);
      for (let i = 0; i < 3; i++) c.target[i] += (-dx * view[i * 4] + dy * view[i * 4 + 1]) * s;
    } else {
      c.yaw -= dx * 0.008;
      c.pitch = Math.max(-1.55, Math.min(1.55, c.pitch + dy * 0.008));
    }
    requestRender();
  });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    zoom(Math.exp(e.deltaY * 0.0015));
  }, { passive: false });
  canvas.addEventListener('dblclick', resetCamera);
  window.addEventListener('resize', requestRender);
  $('file').addEventListener('change', (e) => {
    const f = e.target.files[0];
    if (f) loadFile(f).catch(showError);
  });
  for (const id of ['groups', 'edges', 'wire']) $(id).addEventListener('change', requestRender);
  $('lod').addEventListener('change', (e) => { state.lod = e.target.value; state.lastExtract = 0; requestRender(); });
  $('target').value = state.target;
  $('targetv').textContent = state.target;
  $('target').addEventListener('input', (e) => {
    state.target = Number(e.target.value);
    $('targetv').textContent = state.target;
    requestRender();
  });
  document.addEventListener('dragover', (e) => { e.preventDefault(); document.body.classList.add('dragging'); });
  document.addEventListener('dragleave', () => document.body.classList.remove('dragging'));
  document.addEventListener('drop', (e) => {
    e.preventDefault();
    document.body.classList.remove('dragging');
    const f = e.dataTransfer.files[0];
    if (f) loadFile(f).catch(showError);
  });
}

function zoom(factor) {
  const c = state.camera;
  c.dist = Math.max(c.radius * 1e-3, Math.min(c.radius * 100, c.dist * factor));
  requestRender();
}

// ---------------------------------------------------------------- start
window.scodeViewer = {
  state, loadUrl, loadBytes, benchmark, zoom, resetCamera,
  /// Orbit angles in radians (yaw about the vertical axis, pitch above the horizon).
  setView(yaw, pitch) { state.camera.yaw = yaw; state.camera.pitch = pitch; requestRender(); },
  /// Renders now and extracts even if the last extraction was recent (for tests).
  renderNow() { state.lastExtract = 0; render(); return this.stats(); },
  stats() {
    return {
      triangles: state.counts.triangles, vertices: state.counts.vertices,
      sharpSegments: state.counts.lineVertices / 2, levels: { ...state.levelStats },
      timings: { ...state.timings }, extractions: state.extractions, frames: state.frames,
      maxLevel: state.model ? state.model.maxLevel : -1, error: state.error,
    };
  },
  ready: null,
};

window.scodeViewer.ready = (async () => {
  try {
    if (!gl) throw new Error('WebGL2 is not available in this browser');
    await init();
    setupGL();
    setupInput();
    updateInfo();
    const file = params.get('file');
    if (file) await loadUrl(file);
    else requestRender();
  } catch (e) {
    showError(e);
  }
})();
