// jawtrack view: the arches and mandible in WebGL2, the rig's sliders in degrees and mm, IK by
// dragging a vertex, keyframes, and the tracked timeline. The server answers every question
// about the rig (src/view/scene.rs); this page draws, picks and keeps the keys.
"use strict";

const $ = (id) => document.getElementById(id);
const NAMES = ["opening", "lateral", "protrusion"];
const UNITS = ["°", "mm", "mm"];
const COLOURS = { upper: [0.93, 0.91, 0.85], lower: [0.80, 0.86, 0.95], mandible: [0.82, 0.74, 0.62] };
const OUT_OF_RANGE = [0.95, 0.45, 0.40];

// What the tests and a curious user can reach from the console.
const view = {
  ready: false,
  error: null,
  params: [0, 0, 0], // the network's, from the last reply
  reply: null,
  keys: [],
  redraws: [], // ms from a slider's input to the frame drawn
  lastDrag: null,
  trackedFrame: null,
};
window.view = view;

// ---- small matrix helpers (column-major, as WebGL takes them) ----
function mul(a, b) {
  const o = new Float64Array(16);
  for (let c = 0; c < 4; c++)
    for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
  return o;
}
function transform(m, p) {
  const w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
  return [0, 1, 2].map((r) => (m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r]) / w);
}
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), o = new Float64Array(16);
  o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1;
  o[14] = (2 * far * near) / (near - far);
  return o;
}
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
function lookAt(eye, at, up) {
  const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
  return Float64Array.from([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
    -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
}
function invert(m) {
  // Gauss-Jordan on a 4x4 (row-major copy of the column-major input).
  const a = [];
  for (let r = 0; r < 4; r++) a.push([0, 1, 2, 3].map((c) => m[c * 4 + r]).concat([0, 1, 2, 3].map((c) => (c === r ? 1 : 0))));
  for (let c = 0; c < 4; c++) {
    let p = c;
    for (let r = c + 1; r < 4; r++) if (Math.abs(a[r][c]) > Math.abs(a[p][c])) p = r;
    [a[c], a[p]] = [a[p], a[c]];
    const d = a[c][c];
    for (let k = 0; k < 8; k++) a[c][k] /= d;
    for (let r = 0; r < 4; r++) if (r !== c) { const f = a[r][c]; for (let k = 0; k < 8; k++) a[r][k] -= f * a[c][k]; }
  }
  const o = new Float64Array(16);
  for (let r = 0; r < 4; r++) for (let c = 0; c < 4; c++) o[c * 4 + r] = a[r][4 + c];
  return o;
}
const IDENTITY = Float64Array.from([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);

// ---- the server ----
async function ask(path, body) {
  const init = body === undefined ? {} : { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) };
  const r = await fetch(path, init);
  if (!r.ok) {
    const e = await r.json().catch(() => ({ error: r.statusText }));
    throw new Error(e.error || r.statusText);
  }
  return r;
}

// ---- WebGL2 ----
const canvas = $("gl");
const gl = canvas.getContext("webgl2", { antialias: false });
const VERTEX = `#version 300 es
in vec3 pos; in vec3 nrm;
uniform mat4 viewProj; uniform mat4 model;
out vec3 n; out vec3 wpos;
void main() { vec4 w = model * vec4(pos, 1.0); wpos = w.xyz; n = mat3(model) * nrm; gl_Position = viewProj * w; }`;
const FRAGMENT = `#version 300 es
precision highp float;
in vec3 n; in vec3 wpos; uniform vec3 colour; uniform vec3 eye; out vec4 o;
void main() {
  vec3 N = normalize(n); vec3 V = normalize(eye - wpos);
  if (dot(N, V) < 0.0) N = -N;
  float d = max(dot(N, normalize(V + vec3(0.0, 0.6, 0.0))), 0.0);
  float s = pow(max(dot(N, normalize(V + normalize(V + vec3(0.0, 0.6, 0.0)))), 0.0), 40.0);
  o = vec4(colour * (0.22 + 0.78 * d) + 0.15 * s, 1.0);
}`;
function program() {
  const shader = (type, src) => {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  };
  const p = gl.createProgram();
  gl.attachShader(p, shader(gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(p, shader(gl.FRAGMENT_SHADER, FRAGMENT));
  gl.bindAttribLocation(p, 0, "pos");
  gl.bindAttribLocation(p, 1, "nrm");
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
}

// A mesh from the server's bytes: counts (u32), positions (f32, mm), indices (u32).
async function loadMesh(name) {
  const buf = await (await ask(`/mesh/${name}.bin`)).arrayBuffer();
  const [nv, nt] = new Uint32Array(buf, 0, 2);
  const positions = new Float32Array(buf, 8, nv * 3);
  const indices = new Uint32Array(buf, 8 + nv * 12, nt * 3);
  const normals = new Float32Array(nv * 3);
  for (let t = 0; t < nt * 3; t += 3) {
    const [a, b, c] = [indices[t], indices[t + 1], indices[t + 2]];
    const pa = [positions[3 * a], positions[3 * a + 1], positions[3 * a + 2]];
    const e1 = sub([positions[3 * b], positions[3 * b + 1], positions[3 * b + 2]], pa);
    const e2 = sub([positions[3 * c], positions[3 * c + 1], positions[3 * c + 2]], pa);
    const f = cross(e1, e2);
    for (const v of [a, b, c]) for (let k = 0; k < 3; k++) normals[3 * v + k] += f[k];
  }
  // The same vertices with fewer triangles, drawn while anything moves.
  const cbuf = await (await ask(`/mesh/${name}.coarse.bin`)).arrayBuffer();
  const [cnv, cnt] = new Uint32Array(cbuf, 0, 2);
  const coarse = new Uint32Array(cbuf, 8 + cnv * 12, cnt * 3);
  const m = { name, positions, normals, indices, count: nt * 3, vao: null, coarse, coarseCount: cnt * 3, coarseVao: null };
  upload(m);
  return m;
}
// The mesh's buffers on the GPU (again after a lost context).
function upload(m) {
  const attributes = [[0, m.positions], [1, m.normals]].map(([loc, data]) => {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    return [loc, b];
  });
  // One vertex array per set of triangles, over the same vertex buffers.
  const vao = (indices) => {
    const v = gl.createVertexArray();
    gl.bindVertexArray(v);
    for (const [loc, b] of attributes) {
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
    }
    const ib = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    return v;
  };
  m.vao = vao(m.indices);
  m.coarseVao = vao(m.coarse);
}

// ---- the scene ----
const state = {
  meshes: {},
  // Something moves (a slider, a drag, the orbit, playback): the coarse meshes are drawn.
  moving: false,
  jaw: IDENTITY,
  outOfRange: false,
  orbit: { yaw: 0.35, pitch: 0.15, dist: 120, target: [0, 0, 0] },
  viewProj: IDENTITY,
  eye: [0, 0, 100],
};
let prog, uViewProj, uModel, uColour, uEye;

function camera() {
  const o = state.orbit;
  const eye = [
    o.target[0] + o.dist * Math.cos(o.pitch) * Math.sin(o.yaw),
    o.target[1] + o.dist * Math.sin(o.pitch),
    o.target[2] + o.dist * Math.cos(o.pitch) * Math.cos(o.yaw),
  ];
  state.eye = eye;
  state.viewProj = mul(perspective(0.6, canvas.width / canvas.height, 1, 2000), lookAt(eye, o.target, [0, 1, 0]));
}

// Motion draws the coarse meshes into half the pixels each way (the browser scales the picture
// up): software WebGL's time goes to vertices and pixels alike. The full meshes at the full
// size come back once nothing has moved for REST_MS.
const REST_MS = 150, MOVING_SCALE = 0.5;
let restTimer = null, restSize = null;
function moved() {
  if (!state.moving) {
    restSize = [canvas.width, canvas.height];
    canvas.width = Math.round(restSize[0] * MOVING_SCALE);
    canvas.height = Math.round(restSize[1] * MOVING_SCALE);
  }
  state.moving = true;
  clearTimeout(restTimer);
  restTimer = setTimeout(() => {
    restTimer = null;
    state.moving = false;
    [canvas.width, canvas.height] = restSize;
    draw();
  }, REST_MS);
}
const onePixel = new Uint8Array(4);
// Draw, wait for the picture to be done (software GL draws asynchronously), return the ms.
function draw() {
  const t0 = performance.now();
  camera();
  gl.viewport(0, 0, canvas.width, canvas.height);
  gl.clearColor(0.17, 0.19, 0.22, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.enable(gl.DEPTH_TEST);
  gl.useProgram(prog);
  gl.uniformMatrix4fv(uViewProj, false, Float32Array.from(state.viewProj));
  gl.uniform3fv(uEye, state.eye);
  for (const [name, m] of Object.entries(state.meshes)) {
    const moving = name !== "upper";
    // The mandible's crowns coincide with the lower arch's: the arch is drawn in front.
    if (name === "mandible") { gl.enable(gl.POLYGON_OFFSET_FILL); gl.polygonOffset(2, 2); }
    else gl.disable(gl.POLYGON_OFFSET_FILL);
    gl.uniformMatrix4fv(uModel, false, Float32Array.from(moving ? state.jaw : IDENTITY));
    gl.uniform3fv(uColour, moving && state.outOfRange ? OUT_OF_RANGE : COLOURS[name]);
    if (state.moving) { gl.bindVertexArray(m.coarseVao); gl.drawElements(gl.TRIANGLES, m.coarseCount, gl.UNSIGNED_INT, 0); }
    else { gl.bindVertexArray(m.vao); gl.drawElements(gl.TRIANGLES, m.count, gl.UNSIGNED_INT, 0); }
  }
  gl.bindVertexArray(null);
  // Reading a pixel back waits for the picture to be finished, as finish() need not.
  gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, onePixel);
  drawMarks();
  return performance.now() - t0;
}

// ---- picking and projection ----
function movingPart() {
  return state.meshes.mandible ? "mandible" : "lower";
}
function posed(part, vertex) {
  const p = state.meshes[part].positions;
  const at = [p[3 * vertex], p[3 * vertex + 1], p[3 * vertex + 2]];
  // The upper arch is drawn where it is; the others move with the jaw.
  return part === "upper" ? at : transform(state.jaw, at);
}
// A point of the upper frame in the canvas' CSS pixels, with its depth (NDC z).
function toCanvas(point) {
  const c = transform(state.viewProj, point);
  const r = canvas.getBoundingClientRect();
  return [((c[0] + 1) / 2) * r.width, ((1 - c[1]) / 2) * r.height, c[2]];
}
// The point of the upper frame under a canvas pixel, on the plane through `through` facing the viewer.
function underCursor(x, y, through) {
  const r = canvas.getBoundingClientRect();
  const nx = (2 * x) / r.width - 1, ny = 1 - (2 * y) / r.height;
  const inv = invert(state.viewProj);
  const a = transform(inv, [nx, ny, -1]), b = transform(inv, [nx, ny, 1]);
  const dir = sub(b, a), normal = norm(sub(state.eye, state.orbit.target));
  const t = dot(sub(through, a), normal) / dot(dir, normal);
  return [a[0] + t * dir[0], a[1] + t * dir[1], a[2] + t * dir[2]];
}
// The front-most vertex of `parts` (the moving ones unless said) within 10 px of the cursor.
function pick(x, y, parts = ["mandible", "lower"]) {
  let best = null;
  for (const part of parts) {
    const m = state.meshes[part];
    if (!m) continue;
    const n = m.positions.length / 3;
    for (let v = 0; v < n; v++) {
      const [sx, sy, sz] = toCanvas(posed(part, v));
      const d = Math.hypot(sx - x, sy - y);
      if (d < 10 && (!best || sz < best.depth - 1e-4 || (Math.abs(sz - best.depth) <= 1e-4 && d < best.d)))
        best = { part, vertex: v, depth: sz, d };
    }
  }
  return best;
}

const marks = $("marks").getContext("2d");
let drag = null;
function drawMarks() {
  marks.clearRect(0, 0, 760, 560);
  const dot = (p, colour) => {
    const [x, y] = toCanvas(p);
    marks.fillStyle = colour;
    marks.beginPath();
    marks.arc(x, y, 4, 0, 2 * Math.PI);
    marks.fill();
  };
  // The first pose's picked points, numbered.
  fp.points.forEach((pt, i) => {
    if (!state.meshes[pt.arch]) return;
    const p = posed(pt.arch, pt.vertex);
    dot(p, i === fp.current ? "#ffffff" : PICK_COLOURS[pt.arch]);
    const [x, y] = toCanvas(p);
    marks.fillStyle = "#fff"; marks.font = "12px sans-serif"; marks.fillText(String(i + 1), x + 6, y - 6);
  });
  if (!drag) return;
  if (drag.target) dot(drag.target, "#ffeb3b");
  dot(posed(drag.part, drag.vertex), "#ff5252");
}

// ---- the rig's answers ----
let sliderInputAt = null;
function apply(reply, { setSliders }) {
  view.reply = reply;
  view.params = reply.params;
  state.jaw = Float64Array.from(reply.jaw);
  state.outOfRange = !reply.valid;
  const a = reply.animator;
  const values = [a.opening_deg, a.lateral_mm, a.protrusion_mm];
  NAMES.forEach((n, i) => {
    if (setSliders) $(n).value = values[i];
    $(`${n}-value`).textContent = `${values[i].toFixed(UNITS[i] === "°" ? 1 : 2)} ${UNITS[i]}`;
  });
  band("lateral", reply.lateral_range_mm);
  band("protrusion", reply.protrusion_range_mm);
  const status = [];
  status.push(reply.valid ? '<span class="ok">inside the learned ranges</span>' : '<span class="bad">out of range</span>');
  if (!reply.reached) status.push('<span class="bad">the rig reaches no pose with these values</span>');
  status.push(`incisal point ${a.incisal_opening_mm.toFixed(1)} mm down`);
  $("status").innerHTML = status.join("<br>");
  const ms = draw();
  if (sliderInputAt !== null) {
    const total = performance.now() - sliderInputAt;
    sliderInputAt = null;
    view.redraws.push(total);
    $("frame-time").textContent = `redraw ${total.toFixed(1)} ms after the slider moved (drawing ${ms.toFixed(1)} ms)`;
  }
}
// The valid band of a slider, green on its track.
function band(name, range) {
  const s = $(name);
  if (!range) { s.style.background = "#7a3b3b"; return; }
  const lo = Number(s.min), hi = Number(s.max);
  const f = (v) => Math.min(100, Math.max(0, ((v - lo) / (hi - lo)) * 100));
  s.style.background = `linear-gradient(to right, #555 ${f(range[0])}%, #4f8f52 ${f(range[0])}%, #4f8f52 ${f(range[1])}%, #555 ${f(range[1])}%)`;
}

// One question in flight at a time; the newest waiting one goes next.
let inFlight = false, waiting = null;
function enqueue(job) {
  waiting = job;
  if (!inFlight) next();
}
async function next() {
  const job = waiting;
  waiting = null;
  if (!job) return;
  inFlight = true;
  try {
    await job();
  } catch (e) {
    $("status").innerHTML = `<span class="bad">${e.message}</span>`;
  }
  inFlight = false;
  if (waiting) next();
}
function sliderValues() {
  return NAMES.map((n) => Number($(n).value));
}
async function poseFor(target, setSliders) {
  const r = await (await ask("/api/pose", { target, from: view.params })).json();
  apply(r, { setSliders });
  return r;
}
for (const n of NAMES)
  $(n).addEventListener("input", () => {
    sliderInputAt = performance.now();
    moved();
    view.trackedFrame = null;
    enqueue(() => poseFor(sliderValues(), false));
  });

// ---- mouse: orbit, zoom, drag IK ----
let orbiting = null;
canvas.addEventListener("mousedown", (e) => {
  if ($("pick-mode").checked) {
    const arch = document.querySelector("input[name=pick-arch]:checked").value;
    const at = pick(e.offsetX, e.offsetY, [arch]);
    if (at) {
      fp.points.push({ arch, vertex: at.vertex, pixels: {} });
      fp.current = fp.points.length - 1;
      showPicked();
      e.preventDefault();
      return;
    }
  }
  const hit = view.scene && view.scene.rig ? pick(e.offsetX, e.offsetY) : null;
  if (hit) {
    drag = { part: hit.part, vertex: hit.vertex, start: posed(hit.part, hit.vertex), target: null };
    canvas.style.cursor = "move";
  } else {
    orbiting = { x: e.clientX, y: e.clientY, yaw: state.orbit.yaw, pitch: state.orbit.pitch };
    canvas.style.cursor = "grabbing";
  }
  e.preventDefault();
});
function ikTo(target) {
  const d = drag;
  return async () => {
    const r = await (await ask("/api/ik", { part: d.part, vertex: d.vertex, target, from: view.params })).json();
    apply(r, { setSliders: true });
    view.lastDrag = { part: d.part, vertex: d.vertex, target, residual_mm: r.residual_mm, milliseconds: r.milliseconds, reached: posed(d.part, d.vertex) };
  };
}
window.addEventListener("mousemove", (e) => {
  if (drag) {
    const r = canvas.getBoundingClientRect();
    drag.target = underCursor(e.clientX - r.left, e.clientY - r.top, drag.start);
    moved();
    enqueue(ikTo(drag.target));
    drawMarks();
  } else if (orbiting) {
    state.orbit.yaw = orbiting.yaw - (e.clientX - orbiting.x) * 0.01;
    state.orbit.pitch = Math.max(-1.5, Math.min(1.5, orbiting.pitch + (e.clientY - orbiting.y) * 0.01));
    moved();
    draw();
  }
});
window.addEventListener("mouseup", (e) => {
  if (drag && drag.target) {
    const r = canvas.getBoundingClientRect();
    drag.target = underCursor(e.clientX - r.left, e.clientY - r.top, drag.start);
    const finish = ikTo(drag.target);
    enqueue(async () => { await finish(); drag = null; drawMarks(); });
  } else {
    drag = null;
  }
  orbiting = null;
  canvas.style.cursor = "grab";
});
canvas.addEventListener("wheel", (e) => {
  state.orbit.dist = Math.max(20, Math.min(1000, state.orbit.dist * Math.exp(e.deltaY * 0.001)));
  moved();
  draw();
  e.preventDefault();
}, { passive: false });

// ---- keyframes ----
function showKeys() {
  const t = $("keys");
  t.innerHTML = "";
  view.keys.forEach((k, i) => {
    const row = t.insertRow();
    const time = document.createElement("input");
    time.type = "number"; time.step = "0.25"; time.min = "0"; time.value = k.time;
    time.addEventListener("change", () => { moveKey(i, Number(time.value)); });
    row.insertCell().appendChild(time);
    row.insertCell().textContent = `${k.params[0].toFixed(1)}°, ${k.params[1].toFixed(2)}, ${k.params[2].toFixed(2)} mm`;
    const go = document.createElement("button");
    go.textContent = "go"; go.onclick = () => enqueue(() => poseFor(k.params, true));
    const del = document.createElement("button");
    del.textContent = "✕"; del.onclick = () => { view.keys.splice(i, 1); showKeys(); };
    row.insertCell().append(go, del);
  });
}
function sortKeys() {
  view.keys.sort((a, b) => a.time - b.time);
}
function setKey(time) {
  const a = view.reply.animator;
  const params = [a.opening_deg, a.lateral_mm, a.protrusion_mm];
  view.keys = view.keys.filter((k) => Math.abs(k.time - time) > 1e-9);
  view.keys.push({ time, params });
  sortKeys();
  showKeys();
}
function moveKey(i, time) {
  if (!(time >= 0)) return;
  view.keys[i].time = time;
  sortKeys();
  showKeys();
}
// Animator values at time t: linear between keys, held outside them (as `rig animate --animator`).
function valuesAt(t) {
  const k = view.keys;
  if (t <= k[0].time) return k[0].params;
  for (let i = 1; i < k.length; i++)
    if (t <= k[i].time) {
      const f = (t - k[i - 1].time) / (k[i].time - k[i - 1].time);
      return k[i].params.map((v, j) => k[i - 1].params[j] + (v - k[i - 1].params[j]) * f);
    }
  return k[k.length - 1].params;
}
let playing = null;
function play() {
  if (playing) { playing = null; $("play").textContent = "Play"; return; }
  if (view.keys.length < 2) { $("key-status").textContent = "two keys or more to play"; return; }
  const t0 = view.keys[0].time, t1 = view.keys[view.keys.length - 1].time;
  const started = performance.now();
  playing = {};
  $("play").textContent = "Stop";
  const token = playing;
  const step = () => {
    if (playing !== token) return;
    let t = t0 + (performance.now() - started) / 1000;
    if (t > t1) {
      if ($("loop").checked) t = t0 + ((t - t0) % Math.max(t1 - t0, 1e-6));
      else { playing = null; $("play").textContent = "Play"; t = t1; }
    }
    $("key-time").value = t.toFixed(2);
    moved();
    enqueue(() => poseFor(valuesAt(t), true));
    if (playing === token) requestAnimationFrame(step);
  };
  step();
}
function keysJson() {
  return JSON.stringify(view.keys.map((k) => ({ time: k.time, params: k.params })), null, 1);
}
function importKeys(text) {
  const keys = JSON.parse(text);
  if (!Array.isArray(keys) || !keys.every((k) => Number.isFinite(k.time) && Array.isArray(k.params) && k.params.length === 3 && k.params.every(Number.isFinite)))
    throw new Error('keys: expected [{"time": s, "params": [opening °, lateral mm, protrusion mm]}, ...]');
  view.keys = keys.map((k) => ({ time: k.time, params: k.params.slice() }));
  sortKeys();
  showKeys();
}
async function exportGltf() {
  const fps = Number($("fps").value);
  const r = await ask("/api/animation", { keys: view.keys, fps });
  return r.text();
}
function download(name, text, type) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(new Blob([text], { type }));
  a.download = name;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}
$("set-key").onclick = () => setKey(Number($("key-time").value));
$("play").onclick = play;
$("export-keys").onclick = () => download("keys.json", keysJson(), "application/json");
$("export-gltf").onclick = async () => {
  try {
    download("jaw-animation.gltf", await exportGltf(), "model/gltf+json");
    $("key-status").textContent = "glTF written (Blender: File → Import → glTF 2.0)";
  } catch (e) {
    $("key-status").textContent = e.message;
  }
};
$("import-keys-button").onclick = () => $("import-keys").click();
$("import-keys").addEventListener("change", async (e) => {
  try { importKeys(await e.target.files[0].text()); $("key-status").textContent = `${view.keys.length} keys read`; }
  catch (err) { $("key-status").textContent = err.message; }
});

// ---- the tracked timeline ----
// Opening on the left axis (degrees), lateral and protrusion on the right (mm), frames along
// the bottom; frames the tracker flagged are bands behind the curves.
const TL = { left: 52, right: 52, top: 8, bottom: 22 };
const SERIES = [["opening_deg", "#64b5f6"], ["lateral_mm", "#ffb74d"], ["protrusion_mm", "#81c784"]];
// Round ticks (1, 2 or 5 times a power of ten) covering lo..hi.
function ticks(lo, hi, count) {
  if (!(hi > lo)) { lo -= 1; hi += 1; }
  const raw = (hi - lo) / count, p = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * p).find((s) => s >= raw);
  const first = Math.floor(lo / step + 1e-9) * step, out = [];
  for (let v = first; v < hi + step - 1e-9 * step; v += step) out.push(Number(v.toFixed(10)));
  return out;
}
function timelineGeometry(tl) {
  const c = $("timeline"), w = c.width, h = c.height, n = tl.frames.length;
  const x0 = TL.left, x1 = w - TL.right, y0 = TL.top, y1 = h - TL.bottom;
  const x = (i) => (n === 1 ? (x0 + x1) / 2 : x0 + (i / (n - 1)) * (x1 - x0));
  const at = (px) => Math.max(0, Math.min(n - 1, Math.round(((px - x0) / (x1 - x0)) * (n - 1))));
  const values = (k) => tl.frames.map((f) => f.animator[k]);
  const deg = ticks(Math.min(...values("opening_deg")), Math.max(...values("opening_deg")), 4);
  const mmAll = values("lateral_mm").concat(values("protrusion_mm"));
  const mm = ticks(Math.min(...mmAll), Math.max(...mmAll), 4);
  const frames = ticks(tl.frames[0].frame, tl.frames[n - 1].frame, 10)
    .filter((f) => f >= tl.frames[0].frame && f <= tl.frames[n - 1].frame);
  const y = (v, t) => y1 - ((v - t[0]) / (t[t.length - 1] - t[0])) * (y1 - y0);
  return { w, h, n, x0, x1, y0, y1, x, at, y, deg, mm, frames };
}
function drawTimeline(tl, at, hover) {
  const G = timelineGeometry(tl), g = $("timeline").getContext("2d");
  view.timelineAxes = { degrees: G.deg, mm: G.mm, frames: G.frames };
  g.fillStyle = "#2c3138"; g.fillRect(0, 0, G.w, G.h);
  const band = (G.x1 - G.x0) / Math.max(G.n - 1, 1);
  tl.frames.forEach((f, i) => {
    if (f.status === "ok") return;
    g.fillStyle = f.status === "low-confidence" ? "rgba(229,57,53,0.35)" : "rgba(160,160,160,0.3)";
    g.fillRect(G.x(i) - band / 2, G.y0, Math.max(band, 2), G.y1 - G.y0);
  });
  g.font = "11px sans-serif"; g.lineWidth = 1;
  // Grid and labels: degrees left, millimetres right, frames below.
  g.textBaseline = "middle";
  G.deg.forEach((v) => {
    const py = G.y(v, G.deg);
    g.strokeStyle = "#3d444d"; g.beginPath(); g.moveTo(G.x0, py); g.lineTo(G.x1, py); g.stroke();
    g.fillStyle = "#64b5f6"; g.textAlign = "right"; g.fillText(`${v}°`, G.x0 - 4, py);
  });
  G.mm.forEach((v) => {
    g.fillStyle = "#ffcc80"; g.textAlign = "left"; g.fillText(`${v} mm`, G.x1 + 4, G.y(v, G.mm));
  });
  g.textBaseline = "top"; g.textAlign = "center"; g.fillStyle = "#ccc";
  const first = tl.frames[0].frame, last = tl.frames[G.n - 1].frame;
  G.frames.forEach((f) => {
    const px = G.n === 1 ? G.x(0) : G.x0 + ((f - first) / Math.max(last - first, 1)) * (G.x1 - G.x0);
    g.strokeStyle = "#888"; g.beginPath(); g.moveTo(px, G.y1); g.lineTo(px, G.y1 + 4); g.stroke();
    g.fillText(String(f), px, G.y1 + 6);
  });
  g.strokeStyle = "#888"; g.strokeRect(G.x0, G.y0, G.x1 - G.x0, G.y1 - G.y0);
  for (const [key, colour] of SERIES) {
    const t = key === "opening_deg" ? G.deg : G.mm;
    g.strokeStyle = colour; g.lineWidth = 1.5; g.beginPath();
    tl.frames.forEach((f, i) => { const py = G.y(f.animator[key], t); if (i) g.lineTo(G.x(i), py); else g.moveTo(G.x(i), py); });
    g.stroke();
  }
  g.lineWidth = 1;
  g.fillStyle = "#66bb6a";
  tl.frames.forEach((f, i) => {
    if (!f.hand_set) return;
    g.beginPath(); g.moveTo(G.x(i) - 5, G.y0); g.lineTo(G.x(i) + 5, G.y0); g.lineTo(G.x(i), G.y0 + 8); g.fill();
  });
  g.strokeStyle = "#fff"; g.beginPath(); g.moveTo(G.x(at), G.y0); g.lineTo(G.x(at), G.y1); g.stroke();
  if (hover !== undefined && hover !== at) {
    g.setLineDash([3, 3]); g.strokeStyle = "#bbb";
    g.beginPath(); g.moveTo(G.x(hover), G.y0); g.lineTo(G.x(hover), G.y1); g.stroke();
    g.setLineDash([]);
  }
}
// What the timeline says of frame i, in words.
function frameReadout(tl, i) {
  const f = tl.frames[i], a = f.animator;
  return `frame ${f.frame} (${f.status}${f.hand_set ? ", hand-set" : ""}${f.drafted ? ", moved and not saved" : ""}): opening ${a.opening_deg.toFixed(1)}°, lateral ${a.lateral_mm.toFixed(2)} mm, protrusion ${a.protrusion_mm.toFixed(2)} mm`;
}
function showFrame(tl, i) {
  const f = tl.frames[i];
  view.trackedFrame = f.frame;
  state.jaw = Float64Array.from(f.jaw);
  state.outOfRange = false;
  const a = f.animator, values = [a.opening_deg, a.lateral_mm, a.protrusion_mm];
  NAMES.forEach((n, k) => { $(n).value = values[k]; $(`${n}-value`).textContent = `${values[k].toFixed(k ? 2 : 1)} ${UNITS[k]}`; });
  $("frame-label").textContent = `frame ${f.frame} (${f.status}${f.hand_set ? ", hand-set" : ""}): the tracked pose; the overlays draw the upper arch red, the lower yellow, the boundary of interest green, the mask white`;
  showOverlays(tl, f.frame);
  if (wb.draft && wb.draft.frame !== f.frame) { wb.draft = null; $("terms").innerHTML = ""; }
  $("timeline-readout").textContent = frameReadout(tl, i);
  drawTimeline(tl, i);
  draw();
}
function setupTimeline(tl) {
  $("track").hidden = false;
  const scrub = $("scrub");
  scrub.max = tl.frames.length - 1;
  for (const cam of tl.cameras) {
    const img = document.createElement("img");
    img.id = `overlay-${cam}`; img.alt = cam; img.title = cam;
    $("overlays").appendChild(img);
  }
  scrub.addEventListener("input", () => showFrame(tl, Number(scrub.value)));
  // The canvas may be drawn smaller than its pixels: pointer positions are scaled to them.
  const frameAt = (e) => timelineGeometry(tl).at((e.offsetX * e.target.width) / e.target.clientWidth);
  $("timeline").addEventListener("click", (e) => {
    const i = frameAt(e);
    scrub.value = i;
    showFrame(tl, i);
  });
  $("timeline").addEventListener("mousemove", (e) => {
    const i = frameAt(e);
    $("timeline-readout").textContent = frameReadout(tl, i);
    drawTimeline(tl, Number(scrub.value), i);
  });
  $("timeline").addEventListener("mouseleave", () => {
    $("timeline-readout").textContent = frameReadout(tl, Number(scrub.value));
    drawTimeline(tl, Number(scrub.value));
  });
  showOverlays(tl, tl.frames[0].frame);
  $("timeline-readout").textContent = frameReadout(tl, 0);
  drawTimeline(tl, 0);
  setupWorkbench(tl);
}

// ---- the workbench: a frame's arches moved by hand, saved, the frames after it tracked again ----
const wb = { ops: [], busy: false, drag: null, draft: null, version: 0, shown: 0, polling: false };
// Each camera's picture of `frame`; `shown` changes with every move so the browser asks again.
function showOverlays(tl, frame) {
  wb.shown++;
  for (const cam of tl.cameras) $(`overlay-${cam}`).src = `/overlay/${encodeURIComponent(cam)}/${frame}.png?v=${wb.version}.${wb.shown}`;
}
function workStatus(text, bad) {
  $("work-status").innerHTML = "";
  const s = document.createElement("span");
  if (bad) s.className = "bad";
  s.textContent = text;
  $("work-status").appendChild(s);
}
const editArch = () => document.querySelector("input[name=edit-arch]:checked").value;
// Moves of one kind in one camera add up while a request is out: the server sees their sum.
function queueEdit(tl, op) {
  const last = wb.ops[wb.ops.length - 1];
  if (last && last.kind === op.kind && last.camera === op.camera && last.arch === op.arch && op.kind !== "reset")
    last.v = last.v.map((x, i) => x + op.v[i]);
  else wb.ops.push(op);
  if (!wb.busy) flushEdits(tl);
}
function opJson(op) {
  switch (op.kind) {
    case "drag": return { drag: { camera: op.camera, pixels: op.v } };
    case "turn": return { turn: { camera: op.camera, degrees: op.v } };
    case "depth": return { depth: { camera: op.camera, mm: op.v[0] } };
    case "nudge": return { nudge: { mm: op.v.slice(0, 3), degrees: op.v.slice(3) } };
    default: return "reset";
  }
}
async function flushEdits(tl) {
  wb.busy = true;
  try {
    while (wb.ops.length) {
      const op = wb.ops.shift();
      const d = await (await ask("/api/edit", { frame: view.trackedFrame, arch: op.arch, op: opJson(op) })).json();
      showDraft(tl, d);
    }
  } catch (e) {
    wb.ops = [];
    workStatus(e.message, true);
  }
  wb.busy = false;
}
// A frame as moved: its energy's terms against the saved poses', the jaw in the 3-D view.
function showDraft(tl, d) {
  wb.draft = d;
  const shown = tl.frames.find((f) => f.frame === d.frame);
  if (shown) shown.drafted = d.drafted;
  const i = Number($("scrub").value);
  if (tl.frames[i] && tl.frames[i].frame === d.frame) $("timeline-readout").textContent = frameReadout(tl, i);
  const row = (name, key, digits) => `<tr><td>${name}</td>` + ["upper", "lower"].map((a) => {
    const now = d.terms[a][key], was = d.saved[a][key];
    return `<td>${now.toFixed(digits)}</td><td class="hint">${now === was ? "" : `was ${was.toFixed(digits)}`}</td>`;
  }).join("") + "</tr>";
  $("terms").innerHTML = `<tr><td>frame ${d.frame}${d.hand_set ? " (hand-set)" : ""}</td><td>upper</td><td></td><td>lower</td><td></td></tr>` +
    row("uncovered mask (px)", "uncovered", 0) + row("boundary of interest outside (px)", "boi_outside", 0) +
    row("over the other arch (px)", "cross", 0) + row("over the mouth interior (px)", "over_mouth", 0) +
    row("paper's E", "paper", 1) + row("objective", "objective", 1) + row("area error (%)", "area_error_percent", 2);
  state.jaw = Float64Array.from(d.jaw);
  draw();
  showOverlays(tl, d.frame);
}
async function refreshTimeline(tl) {
  const t = await (await ask("/api/timeline")).json();
  tl.frames = t.frames;
  wb.version = t.version;
  const i = Number($("scrub").value);
  $("timeline-readout").textContent = frameReadout(tl, i);
  drawTimeline(tl, i);
  if (!wb.draft) showFrame(tl, i);
  return t;
}
function showJob(j) {
  $("retrack").disabled = $("retrack-back").disabled = j.running;
  $("stop-retrack").disabled = !j.running;
  if (j.from === null || j.from === undefined) return;
  const first = j.first_frame_seconds === null ? "" : `; the first in ${j.first_frame_seconds.toFixed(2)} s`;
  const way = j.backward ? `backwards from frame ${j.from} down to ${j.until}` : `from frame ${j.from} up to ${j.until}`;
  workStatus(`${j.running ? "re-tracking" : "re-tracked"} ${way}: ${j.done} frames${j.last === null ? "" : ` (last ${j.last})`}${first}. ${j.message}`);
}
async function pollJob(tl) {
  if (wb.polling) return;
  wb.polling = true;
  try {
    for (;;) {
      const j = await (await ask("/api/retrack")).json();
      showJob(j);
      if (j.version !== wb.version) await refreshTimeline(tl);
      if (!j.running) break;
      await new Promise((r) => setTimeout(r, 250));
    }
  } catch (e) {
    workStatus(e.message, true);
  }
  wb.polling = false;
}
function setupWorkbench(tl) {
  for (const cam of tl.cameras) {
    const img = $(`overlay-${cam}`);
    img.draggable = false;
    img.addEventListener("mousedown", (e) => {
      e.preventDefault();
      // Pointer pixels to the picture's own (the masks'), which the server moves the arch by,
      // at the scale the picture had when it was grabbed: the page may lay out again while the
      // arch moves (the frame's terms appear), and one drag would be scaled two ways.
      wb.drag = { cam, s: img.naturalWidth / img.clientWidth, x: e.clientX, y: e.clientY };
    });
    img.addEventListener("wheel", (e) => {
      e.preventDefault();
      queueEdit(tl, { kind: "depth", arch: editArch(), camera: cam, v: [0.1 * Math.sign(e.deltaY)] });
    }, { passive: false });
  }
  window.addEventListener("mousemove", (e) => {
    const d = wb.drag;
    if (!d) return;
    const dx = (e.clientX - d.x) * d.s, dy = (e.clientY - d.y) * d.s;
    d.x = e.clientX; d.y = e.clientY;
    if (dx === 0 && dy === 0) return;
    if (e.shiftKey) queueEdit(tl, { kind: "turn", arch: editArch(), camera: d.cam, v: [0.25 * dx, 0.25 * dy] });
    else queueEdit(tl, { kind: "drag", arch: editArch(), camera: d.cam, v: [dx, dy] });
  });
  window.addEventListener("mouseup", () => { wb.drag = null; });
  // Keys move the arch along its own axes (x left-right, y up-down, z front-back).
  const KEYS = { ArrowLeft: [0, -1], ArrowRight: [0, 1], ArrowUp: [1, 1], ArrowDown: [1, -1], PageUp: [2, 1], PageDown: [2, -1] };
  window.addEventListener("keydown", (e) => {
    const k = KEYS[e.key];
    if (!k || $("track").hidden || ["INPUT", "TEXTAREA", "SELECT"].includes(document.activeElement.tagName) && document.activeElement.type !== "radio") return;
    e.preventDefault();
    const v = [0, 0, 0, 0, 0, 0];
    if (e.shiftKey) v[3 + [1, 0, 2][k[0]]] = 0.25 * k[1]; else v[k[0]] = 0.1 * k[1];
    queueEdit(tl, { kind: "nudge", arch: editArch(), v });
  });
  $("reset-frame").addEventListener("click", () => queueEdit(tl, { kind: "reset", arch: editArch(), v: [] }));
  $("save-frame").addEventListener("click", async () => {
    try {
      while (wb.busy) await new Promise((r) => setTimeout(r, 20));
      const d = await (await ask("/api/correct", { frame: view.trackedFrame })).json();
      showDraft(tl, d);
      await refreshTimeline(tl);
      workStatus(`frame ${d.frame} saved as hand-set in tracks.json (the file as first read: ${view.scene.timeline.backup})`);
    } catch (e) { workStatus(e.message, true); }
  });
  const retrack = async (backward) => {
    try {
      showJob(await (await ask("/api/retrack", { frame: view.trackedFrame, backward })).json());
      wb.draft = null;
      pollJob(tl);
    } catch (e) { workStatus(e.message, true); }
  };
  $("retrack").addEventListener("click", () => retrack(false));
  $("retrack-back").addEventListener("click", () => retrack(true));
  $("stop-retrack").addEventListener("click", async () => {
    try { showJob(await (await ask("/api/retrack/stop", {})).json()); } catch (e) { workStatus(e.message, true); }
  });
  showJob(tl.job);
  if (tl.job.running) pollJob(tl);
}

// ---- the first pose: points picked on the models and in the pictures, fitted, init.json ----
const PICK_COLOURS = { upper: "#ff5252", lower: "#ffd740" };
const fp = { points: [], current: -1, shown: 0, frame: 0, cameras: [], crops: {} };
function pickStatus(text, bad) {
  $("pick-status").textContent = text;
  $("pick-status").className = bad ? "hint bad" : "hint";
}
function showPictures() {
  fp.shown++;
  for (const cam of fp.cameras) $(`picture-${cam}`).src = `/picture/${encodeURIComponent(cam)}/${fp.frame}.png?v=${fp.shown}`;
}
// The picked points in the table and on each picture.
function showPicked(residuals) {
  const t = $("picked");
  t.innerHTML = "";
  fp.points.forEach((pt, i) => {
    const row = t.insertRow();
    if (i === fp.current) row.className = "current";
    const where = Object.entries(pt.pixels).map(([c, p]) => `${c} (${p[0].toFixed(1)}, ${p[1].toFixed(1)})`).join(", ");
    const r = residuals ? residuals[pt.arch][fp.points.filter((q) => q.arch === pt.arch).indexOf(pt)] : undefined;
    row.insertCell().textContent = `${i + 1}: ${pt.arch} vertex ${pt.vertex}`;
    row.insertCell().textContent = where || "click it in two or more pictures";
    row.insertCell().textContent = r === undefined ? "" : `off by ${r.toFixed(1)} px`;
    row.addEventListener("click", () => { fp.current = i; showPicked(residuals); });
  });
  for (const cam of fp.cameras) {
    const img = $(`picture-${cam}`), c = $(`picture-marks-${cam}`);
    c.width = img.clientWidth; c.height = img.clientHeight;
    const g = c.getContext("2d"), s = img.clientWidth / (img.naturalWidth || 1);
    const o = fp.crops[cam];
    fp.points.forEach((pt, i) => {
      const p = pt.pixels[cam];
      if (!p) return;
      const x = (p[0] - o[0] + 0.5) * s, y = (p[1] - o[1] + 0.5) * s;
      g.strokeStyle = i === fp.current ? "#ffffff" : PICK_COLOURS[pt.arch]; g.lineWidth = 1.5;
      g.beginPath(); g.moveTo(x - 5, y); g.lineTo(x + 5, y); g.moveTo(x, y - 5); g.lineTo(x, y + 5); g.stroke();
      g.fillStyle = "#fff"; g.font = "11px sans-serif"; g.fillText(String(i + 1), x + 5, y - 5);
    });
  }
  drawMarks();
}
async function fitPose(write) {
  const body = { upper: [], lower: [], write };
  for (const pt of fp.points) body[pt.arch].push({ vertex: pt.vertex, pixels: pt.pixels });
  try {
    const r = await (await ask("/api/first-pose", body)).json();
    fp.fitted = r;
    showPicked(r.residual_px);
    showPictures();
    const worst = Math.max(...r.residual_px.upper, ...r.residual_px.lower);
    pickStatus(r.written ? `init.json written: ${r.written}${r.kept ? ` (the one before kept as ${r.kept})` : ""}; clicks within ${worst.toFixed(1)} px of the fitted pose` : `fitted: the clicks are within ${worst.toFixed(1)} px of the fitted pose, drawn over the pictures`);
  } catch (e) { pickStatus(e.message, true); }
}
function setupFirstPose(info) {
  $("first-pose").hidden = false;
  fp.frame = info.first_frame;
  fp.cameras = info.cameras;
  // Where each picture shown starts in the whole one.
  fp.crops = Object.fromEntries(info.cameras.map((c, k) => [c, info.crops[k] || [0, 0]]));
  for (const cam of info.cameras) {
    const box = document.createElement("div");
    box.className = "picture";
    const img = document.createElement("img");
    img.id = `picture-${cam}`; img.alt = cam; img.title = cam; img.draggable = false;
    const marksCanvas = document.createElement("canvas");
    marksCanvas.id = `picture-marks-${cam}`;
    box.append(img, marksCanvas);
    $("pictures").appendChild(box);
    img.addEventListener("load", () => showPicked(fp.fitted && fp.fitted.residual_px));
    img.addEventListener("click", (e) => {
      const pt = fp.points[fp.current];
      if (!pt) { pickStatus("pick a point on the model first (Pick on, then click the 3-D view)", true); return; }
      // The whole picture's own pixels (the masks'), whatever part and size is shown.
      const s = img.naturalWidth / img.clientWidth, o = fp.crops[cam];
      pt.pixels[cam] = [o[0] + e.offsetX * s - 0.5, o[1] + e.offsetY * s - 0.5];
      showPicked();
    });
  }
  $("fit-pose").addEventListener("click", () => fitPose(false));
  $("write-init").addEventListener("click", () => fitPose(true));
  $("clear-points").addEventListener("click", () => { fp.points = []; fp.current = -1; showPicked(); });
  showPictures();
  if (!info.has_init) pickStatus("this capture has no init.json: pick the first pose here, or give `track --locate`");
}

// ---- start ----
function setupProgram() {
  prog = program();
  uViewProj = gl.getUniformLocation(prog, "viewProj");
  uModel = gl.getUniformLocation(prog, "model");
  uColour = gl.getUniformLocation(prog, "colour");
  uEye = gl.getUniformLocation(prog, "eye");
}
// A software GL's process may be restarted under load: the page then draws again from the
// meshes it holds, keeping the pose and the keys.
canvas.addEventListener("webglcontextlost", (e) => {
  e.preventDefault();
  view.contextLost = (view.contextLost || 0) + 1;
});
canvas.addEventListener("webglcontextrestored", () => {
  setupProgram();
  for (const m of Object.values(state.meshes)) upload(m);
  draw();
});

async function start() {
  if (!gl) throw new Error("this browser has no WebGL2");
  setupProgram();
  const scene = await (await ask("/api/scene")).json();
  view.scene = scene;
  $("rig-kind").textContent = scene.rig ? `Rig: the ${scene.rig}` : "No rig: the capture alone";
  // Without a rig there is nothing for the sliders, IK and keys to drive.
  for (const el of document.querySelectorAll(".rig-only")) el.hidden = !scene.rig;
  for (const name of scene.meshes) state.meshes[name] = await loadMesh(name);
  // Look at the teeth: the centre and size of the arches.
  const all = [state.meshes.upper, state.meshes.lower].filter(Boolean);
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (const m of all)
    for (let i = 0; i < m.positions.length; i += 3)
      for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], m.positions[i + k]); hi[k] = Math.max(hi[k], m.positions[i + k]); }
  state.orbit.target = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2);
  state.orbit.dist = 2.2 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  if (scene.rig) {
    const ex = scene.extent, ranges = [ex.opening_deg, ex.lateral_mm, ex.protrusion_mm];
    NAMES.forEach((n, i) => { $(n).min = ranges[i][0]; $(n).max = ranges[i][1]; });
    apply(scene.rest, { setSliders: true });
  } else draw();
  if (scene.timeline) setupTimeline(scene.timeline);
  if (scene.capture) setupFirstPose(scene.capture);
  // `?opening=12&lateral=1&protrusion=2` opens the page at that pose (a link to a pose).
  const asked = NAMES.map((n) => Number(new URLSearchParams(location.search).get(n) || 0));
  if (asked.some((v) => v !== 0)) await poseFor(asked, true);
  view.ready = true;
}

// The tests' handles: the page's own functions, driven as a user would.
Object.assign(view, {
  draw, pick, posed, toCanvas, setKey, keysJson, importKeys, exportGltf, valuesAt,
  setOrbit: (yaw, pitch, dist) => { Object.assign(state.orbit, { yaw, pitch }); if (dist) state.orbit.dist = dist; draw(); },
  canvasRect: () => { const r = canvas.getBoundingClientRect(); return { x: r.left, y: r.top, width: r.width, height: r.height }; },
  movingPart,
  vertexCount: (part) => (state.meshes[part] ? state.meshes[part].positions.length / 3 : 0),
  vertexPosition: (part, v) => Array.from(state.meshes[part].positions.slice(3 * v, 3 * v + 3)),
  dragging: () => drag !== null,
  jaw: () => Array.from(state.jaw),
  poseFor: (target) => poseFor(target, true),
  // Answered and drawn at rest (the full meshes), as a picture to compare must be.
  idle: () => !inFlight && !waiting && !state.moving,
  answered: () => !inFlight && !waiting,
  workIdle: () => !wb.busy && !wb.polling && wb.ops.length === 0,
  draft: () => wb.draft,
  firstPose: () => ({ points: fp.points, current: fp.current, fitted: fp.fitted || null }),
});
// `?bench=N`: sweep the opening slider N times as a user would, then write the page's frame
// times into <pre id="bench"> (benches/view.sh reads it).
async function bench(n) {
  const s = $("opening"), lo = Number(s.min), hi = Number(s.max);
  const draws = [];
  for (let k = 0; k < n; k++) {
    const done = view.redraws.length;
    // Back and forth over the first two thirds of the travel in 0.5° steps, as a hand drags.
    const span = Math.floor(((hi - lo) * 2) / 3 / 0.5), i = k % (2 * span);
    s.value = lo + 0.5 * (i < span ? i : 2 * span - i);
    s.dispatchEvent(new Event("input"));
    while (view.redraws.length === done || !view.answered()) await new Promise((r) => setTimeout(r, 1));
    draws.push(draw());
  }
  // Then at rest: the full meshes, as drawn once the slider stops.
  while (state.moving) await new Promise((r) => setTimeout(r, 10));
  const rest = [];
  for (let k = 0; k < 10; k++) rest.push(draw());
  const sorted = (a) => a.slice().sort((x, y) => x - y);
  const t = sorted(view.redraws.slice(1)), d = sorted(draws), r = sorted(rest);
  const triangles = Object.values(state.meshes).reduce((a, m) => a + m.count / 3, 0);
  const coarse = Object.values(state.meshes).reduce((a, m) => a + m.coarseCount / 3, 0);
  const pre = document.createElement("pre");
  pre.id = "bench";
  pre.textContent = JSON.stringify({ moves: t.length, triangles, coarse_triangles: coarse, slider_to_frame_ms: { median: t[t.length >> 1], max: t[t.length - 1] }, draw_ms: { median: d[d.length >> 1], max: d[d.length - 1] }, rest_draw_ms: { median: r[r.length >> 1], max: r[r.length - 1] }, contexts_lost: view.contextLost || 0 });
  document.body.appendChild(pre);
}
const query = new URLSearchParams(location.search);
const benchMoves = Number(query.get("bench"));
if (query.get("scale")) { canvas.width = Math.round(760 * Number(query.get("scale"))); canvas.height = Math.round(560 * Number(query.get("scale"))); }
start().then(() => (benchMoves > 0 ? bench(benchMoves) : null)).catch((e) => {
  view.error = e.message;
  $("status").innerHTML = `<span class="bad">${e.message}</span>`;
});
