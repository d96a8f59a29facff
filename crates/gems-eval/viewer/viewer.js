// gems WebGL2 Gaussian-splat viewer. Embedded by crates/gems-eval/src/viewer.rs into
// report.html and viewer.html together with window.GEMS_SCENE; no network access.
//
// The projection is the one of gems' engine (gsplat 1.5 semantics, crates/gems-splat):
// pinhole OpenCV camera (x right, y down, z forward; x_cam = R x_world + t), EWA 2D covariance
// J W Σ Wᵀ Jᵀ with the 0.3·tan_fov guard band on J, eps2d 0.3 added to the diagonal, a box of
// 3.33 σ per axis, α = min(0.999, o·exp(−σ)), α < 1/255 skipped, colour
// max(SH(mean − centre) + 0.5, 0) up to degree 1. Splats are depth-sorted (counting sort over
// 16-bit depth keys) and blended back to front, premultiplied; the background is black.
(function () {
  "use strict";
  const S = window.GEMS_SCENE;
  const root = document.getElementById("gems-viewer");
  const hash = new URLSearchParams(location.hash.slice(1));
  const startCam = hash.get("camera");
  // With #camera=<name> the page is a clean view of that camera (no overlays) until the mouse
  // moves or a key is pressed, so a screenshot compares with gems' render.
  let clean = startCam !== null;

  const style = document.createElement("style");
  style.textContent =
    "#gems-viewer{position:relative;background:#000;user-select:none}" +
    "#gems-viewer.gems-full{position:fixed;inset:0}" +
    "#gems-viewer.gems-box{width:100%;aspect-ratio:16/9}" +
    "#gems-viewer canvas{position:absolute;left:0;top:0;width:100%;height:100%;display:block;outline:none}" +
    "#gems-viewer .ov{position:absolute;left:0;top:0;width:100%;height:100%;object-fit:fill;display:none;pointer-events:none}" +
    "#gems-viewer .ui{position:absolute;left:6px;top:6px;right:6px;font:12px sans-serif;color:#eee}" +
    "#gems-viewer .ui button{font:11px sans-serif;margin:1px;padding:1px 4px;background:#333;color:#eee;border:1px solid #666;border-radius:3px;cursor:pointer}" +
    "#gems-viewer .ui button.on{background:#2a5db0}" +
    "#gems-viewer .ui .row{margin:2px 0;background:rgba(0,0,0,.45);padding:2px 4px;display:inline-block}" +
    "#gems-viewer.clean .ui{display:none}";
  document.head.appendChild(style);

  const canvas = document.createElement("canvas");
  canvas.tabIndex = 0;
  root.appendChild(canvas);
  const overlay = document.createElement("img");
  overlay.className = "ov";
  root.appendChild(overlay);
  const ui = document.createElement("div");
  ui.className = "ui";
  root.appendChild(ui);
  if (clean) root.classList.add("clean");

  const gl = canvas.getContext("webgl2", { antialias: false, premultipliedAlpha: false, preserveDrawingBuffer: true });
  if (!gl) {
    ui.textContent = "WebGL2 is not available in this browser.";
    root.classList.remove("clean");
    return;
  }

  function b64(s) {
    const bin = atob(s);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  // ---- scene data -> float texture: 6 RGBA32F texels per splat ----
  const N = S.count;
  const raw = b64(S.splats);
  const sh1 = new Int8Array(b64(S.sh1).buffer);
  const fv = new DataView(raw.buffer);
  const PER_ROW = 512;
  const texW = PER_ROW * 6;
  const texH = Math.max(1, Math.ceil(N / PER_ROW));
  const tex = new Float32Array(texW * texH * 4);
  const means = new Float32Array(N * 3);
  const C0 = 0.28209479177387814;
  const s1 = S.sh1Scale / 127;
  for (let i = 0; i < N; i++) {
    const o = i * 32;
    const m = [fv.getFloat32(o, true), fv.getFloat32(o + 4, true), fv.getFloat32(o + 8, true)];
    const s = [fv.getFloat32(o + 12, true), fv.getFloat32(o + 16, true), fv.getFloat32(o + 20, true)];
    const rgba = [raw[o + 24], raw[o + 25], raw[o + 26], raw[o + 27]];
    let q = [(raw[o + 28] - 128) / 128, (raw[o + 29] - 128) / 128, (raw[o + 30] - 128) / 128, (raw[o + 31] - 128) / 128];
    const qn = Math.hypot(q[0], q[1], q[2], q[3]) || 1;
    q = q.map((v) => v / qn);
    const [w, x, y, z] = q;
    const Rq = [
      1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ];
    // Σ = R S Sᵀ Rᵀ
    const cov = [0, 0, 0, 0, 0, 0];
    const idx = [[0, 0], [0, 1], [0, 2], [1, 1], [1, 2], [2, 2]];
    for (let k = 0; k < 6; k++) {
      const [a, b] = idx[k];
      let acc = 0;
      for (let l = 0; l < 3; l++) acc += Rq[a * 3 + l] * s[l] * s[l] * Rq[b * 3 + l];
      cov[k] = acc;
    }
    means.set(m, i * 3);
    const base = ((Math.floor(i / PER_ROW) * texW) + (i % PER_ROW) * 6) * 4;
    const h = sh1.subarray(i * 9, i * 9 + 9);
    tex.set([m[0], m[1], m[2], rgba[3] / 255,
      cov[0], cov[1], cov[2], cov[3],
      cov[4], cov[5], rgba[0] / 255, rgba[1] / 255,
      rgba[2] / 255, h[0] * s1, h[1] * s1, h[2] * s1,
      h[3] * s1, h[4] * s1, h[5] * s1, h[6] * s1,
      h[7] * s1, h[8] * s1, 0, 0], base);
  }
  const dataTex = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, dataTex);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, texW, texH, 0, gl.RGBA, gl.FLOAT, tex);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);

  function compile(vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const sh = gl.createShader(type);
      gl.shaderSource(sh, src);
      gl.compileShader(sh);
      if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(sh));
      gl.attachShader(p, sh);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }

  const splatVS = `#version 300 es
precision highp float; precision highp int;
uniform highp sampler2D u_data;
uniform mat3 u_R; uniform vec3 u_t; uniform vec3 u_center;
uniform vec4 u_K; uniform vec2 u_size;
in uint a_index; in vec2 a_corner;
out vec2 v_mean; out vec3 v_conic; out float v_op; out vec3 v_rgb;
vec4 fetch(uint i, int k) {
  int row = int(i / 512u); int col = int(i % 512u) * 6 + k;
  return texelFetch(u_data, ivec2(col, row), 0);
}
void main() {
  vec4 d0 = fetch(a_index, 0), d1 = fetch(a_index, 1), d2 = fetch(a_index, 2), d3 = fetch(a_index, 3), d4 = fetch(a_index, 4), d5 = fetch(a_index, 5);
  vec3 mean = d0.xyz;
  vec3 pc = u_R * mean + u_t;
  gl_Position = vec4(0.0, 0.0, 2.0, 1.0);
  if (!(pc.z > 0.01)) return;
  mat3 cov = mat3(d1.x, d1.y, d1.z, d1.y, d1.w, d2.x, d1.z, d2.x, d2.y);
  mat3 covc = u_R * cov * transpose(u_R);
  float fx = u_K.x, fy = u_K.y, cx = u_K.z, cy = u_K.w;
  float tanx = 0.5 * u_size.x / fx, tany = 0.5 * u_size.y / fy;
  float rx = pc.x / pc.z, ry = pc.y / pc.z;
  float tx = pc.z * clamp(rx, -(cx / fx + 0.3 * tanx), (u_size.x - cx) / fx + 0.3 * tanx);
  float ty = pc.z * clamp(ry, -(cy / fy + 0.3 * tany), (u_size.y - cy) / fy + 0.3 * tany);
  vec3 j0 = vec3(fx / pc.z, 0.0, -fx * tx / (pc.z * pc.z));
  vec3 j1 = vec3(0.0, fy / pc.z, -fy * ty / (pc.z * pc.z));
  vec3 cj0 = covc * j0, cj1 = covc * j1;
  float a = dot(j0, cj0) + 0.3, b = 0.5 * (dot(j0, cj1) + dot(j1, cj0)), c = dot(j1, cj1) + 0.3;
  float det = a * c - b * b;
  if (!(det > 0.0)) return;
  vec2 m2 = vec2(fx * pc.x / pc.z + cx, fy * pc.y / pc.z + cy);
  vec2 r = ceil(3.33 * sqrt(vec2(a, c)));
  if (m2.x + r.x <= 0.0 || m2.x - r.x >= u_size.x || m2.y + r.y <= 0.0 || m2.y - r.y >= u_size.y) return;
  vec3 dir = normalize(mean - u_center);
  vec3 rgb = vec3(d2.z, d2.w, d3.x) - 0.5;
  // SH degree 1 in gsplat's order: −C1·y, C1·z, −C1·x.
  float C1 = 0.4886025119029199;
  rgb += -C1 * dir.y * vec3(d3.y, d3.z, d3.w) + C1 * dir.z * vec3(d4.x, d4.y, d4.z) - C1 * dir.x * vec3(d4.w, d5.x, d5.y);
  v_rgb = max(rgb + 0.5, 0.0);
  v_mean = m2;
  v_conic = vec3(c, -b, a) / det;
  v_op = d0.w;
  vec2 p = m2 + a_corner * r;
  gl_Position = vec4(p.x / u_size.x * 2.0 - 1.0, 1.0 - p.y / u_size.y * 2.0, 0.0, 1.0);
}`;
  const splatFS = `#version 300 es
precision highp float;
uniform vec2 u_size;
in vec2 v_mean; in vec3 v_conic; in float v_op; in vec3 v_rgb;
out vec4 o;
void main() {
  vec2 px = vec2(gl_FragCoord.x, u_size.y - gl_FragCoord.y);
  vec2 d = px - v_mean;
  float sigma = 0.5 * (v_conic.x * d.x * d.x + v_conic.z * d.y * d.y) + v_conic.y * d.x * d.y;
  if (sigma < 0.0) discard;
  float alpha = min(0.999, v_op * exp(-sigma));
  if (alpha < 1.0 / 255.0) discard;
  o = vec4(v_rgb * alpha, alpha);
}`;
  const lineVS = `#version 300 es
precision highp float;
uniform mat3 u_R; uniform vec3 u_t; uniform vec4 u_K; uniform vec2 u_size;
in vec3 a_pos;
void main() {
  vec3 p = u_R * a_pos + u_t;
  float n = 0.01, f = 1000.0;
  gl_Position = vec4(2.0 * u_K.x / u_size.x * p.x + (2.0 * u_K.z / u_size.x - 1.0) * p.z,
                     -2.0 * u_K.y / u_size.y * p.y + (1.0 - 2.0 * u_K.w / u_size.y) * p.z,
                     (f + n) / (f - n) * p.z - 2.0 * f * n / (f - n), p.z);
}`;
  const lineFS = `#version 300 es
precision highp float; uniform vec3 u_color; out vec4 o;
void main() { o = vec4(u_color, 1.0); }`;
  const splatProg = compile(splatVS, splatFS);
  const lineProg = compile(lineVS, lineFS);
  const U = (p, n) => gl.getUniformLocation(p, n);

  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const cornerBuf = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, cornerBuf);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, 1, 1, -1, 1]), gl.STATIC_DRAW);
  let loc = gl.getAttribLocation(splatProg, "a_corner");
  gl.enableVertexAttribArray(loc);
  gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
  const indexBuf = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, indexBuf);
  gl.bufferData(gl.ARRAY_BUFFER, N * 4, gl.DYNAMIC_DRAW);
  loc = gl.getAttribLocation(splatProg, "a_index");
  gl.enableVertexAttribArray(loc);
  gl.vertexAttribIPointer(loc, 1, gl.UNSIGNED_INT, 0, 0);
  gl.vertexAttribDivisor(loc, 1);
  const quadIdx = gl.createBuffer();
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, quadIdx);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint16Array([0, 1, 2, 0, 2, 3]), gl.STATIC_DRAW);
  gl.bindVertexArray(null);

  // Trajectories: one line strip per view, laid out in one buffer.
  const lineVao = gl.createVertexArray();
  gl.bindVertexArray(lineVao);
  const strips = [];
  const pts = [];
  for (const c of S.cameras) {
    if (c.traj.length > 1) {
      strips.push([pts.length / 3, c.traj.length]);
      for (const p of c.traj) pts.push(p[0], p[1], p[2]);
    }
  }
  const lineBuf = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, lineBuf);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(pts), gl.STATIC_DRAW);
  loc = gl.getAttribLocation(lineProg, "a_pos");
  gl.enableVertexAttribArray(loc);
  gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(null);

  // ---- camera state: OpenCV world-to-camera R (row-major array of 9), centre, intrinsics ----
  const ref = S.cameras[0] || { fx: 500, fy: 500, cx: 320, cy: 240, w: 640, h: 480, R: [1, 0, 0, 0, 1, 0, 0, 0, 1], t: [0, 0, 0] };
  let view = { R: ref.R.slice(), C: centre(ref.R, ref.t), K: ref };
  let target = null;
  const sceneCentre = [0, 0, 0];
  for (let i = 0; i < N; i++) for (let k = 0; k < 3; k++) sceneCentre[k] += means[i * 3 + k] / Math.max(N, 1);

  function centre(R, t) {
    return [0, 1, 2].map((i) => -(R[i] * t[0] + R[3 + i] * t[1] + R[6 + i] * t[2]));
  }
  function translation(R, C) {
    return [0, 1, 2].map((i) => -(R[i * 3] * C[0] + R[i * 3 + 1] * C[1] + R[i * 3 + 2] * C[2]));
  }
  // Rotation about a unit axis (Rodrigues), row-major.
  function axisAngle(ax, ang) {
    const [x, y, z] = ax, c = Math.cos(ang), s = Math.sin(ang), k = 1 - c;
    return [c + x * x * k, x * y * k - z * s, x * z * k + y * s,
      y * x * k + z * s, c + y * y * k, y * z * k - x * s,
      z * x * k - y * s, z * y * k + x * s, c + z * z * k];
  }
  function mul(A, B) {
    const o = new Array(9).fill(0);
    for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) for (let k = 0; k < 3; k++) o[i * 3 + j] += A[i * 3 + k] * B[k * 3 + j];
    return o;
  }
  const row = (R, i) => [R[i * 3], R[i * 3 + 1], R[i * 3 + 2]];
  const add = (a, b, s) => [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]];
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];

  function orbitDistance() {
    if (!target) {
      const d = dot(sub(sceneCentre, view.C), row(view.R, 2));
      target = add(view.C, row(view.R, 2), d > 1e-3 ? d : 1);
    }
    return Math.max(1e-3, Math.hypot(...sub(target, view.C)));
  }

  // Canvas-size intrinsics: the view camera's, scaled to the canvas width and centred vertically.
  function intrinsics(w, h) {
    const K = view.K, s = w / K.w;
    return [K.fx * s, K.fy * s, K.cx * s, K.cy * s + (h - K.h * s) / 2];
  }

  // ---- sort: counting sort over 16-bit view depths, far to near ----
  const order = new Uint32Array(N);
  const keys = new Uint16Array(N);
  const counts = new Uint32Array(65536);
  function sortSplats() {
    const R = view.R, t = translation(R, view.C);
    let lo = Infinity, hi = -Infinity;
    const zs = new Float32Array(N);
    for (let i = 0; i < N; i++) {
      const z = R[6] * means[i * 3] + R[7] * means[i * 3 + 1] + R[8] * means[i * 3 + 2] + t[2];
      zs[i] = z;
      if (z < lo) lo = z;
      if (z > hi) hi = z;
    }
    const scale = hi > lo ? 65535 / (hi - lo) : 0;
    counts.fill(0);
    for (let i = 0; i < N; i++) {
      const k = 65535 - Math.floor((zs[i] - lo) * scale);
      keys[i] = k;
      counts[k]++;
    }
    for (let k = 1; k < 65536; k++) counts[k] += counts[k - 1];
    for (let i = N - 1; i >= 0; i--) order[--counts[keys[i]]] = i;
    gl.bindBuffer(gl.ARRAY_BUFFER, indexBuf);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, order);
  }

  let showTraj = !clean;
  let dirty = true;
  function draw() {
    dirty = false;
    const w = canvas.width, h = canvas.height;
    gl.viewport(0, 0, w, h);
    gl.clearColor(0, 0, 0, 1);
    gl.clear(gl.COLOR_BUFFER_BIT);
    const K = intrinsics(w, h);
    const t = translation(view.R, view.C);
    // WebGL's mat3 is column-major: pass Rᵀ's array to get R.
    const Rt = [0, 3, 6, 1, 4, 7, 2, 5, 8].map((i) => view.R[i]);
    if (N > 0) {
      sortSplats();
      gl.useProgram(splatProg);
      gl.uniformMatrix3fv(U(splatProg, "u_R"), false, Rt);
      gl.uniform3fv(U(splatProg, "u_t"), t);
      gl.uniform3fv(U(splatProg, "u_center"), view.C);
      gl.uniform4fv(U(splatProg, "u_K"), K);
      gl.uniform2f(U(splatProg, "u_size"), w, h);
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, dataTex);
      gl.uniform1i(U(splatProg, "u_data"), 0);
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
      gl.bindVertexArray(vao);
      gl.drawElementsInstanced(gl.TRIANGLES, 6, gl.UNSIGNED_SHORT, 0, N);
      gl.bindVertexArray(null);
      gl.disable(gl.BLEND);
    }
    if (showTraj && strips.length) {
      gl.useProgram(lineProg);
      gl.uniformMatrix3fv(U(lineProg, "u_R"), false, Rt);
      gl.uniform3fv(U(lineProg, "u_t"), t);
      gl.uniform4fv(U(lineProg, "u_K"), K);
      gl.uniform2f(U(lineProg, "u_size"), w, h);
      gl.uniform3f(U(lineProg, "u_color"), 1.0, 0.3, 0.2);
      gl.bindVertexArray(lineVao);
      for (const [first, count] of strips) gl.drawArrays(gl.LINE_STRIP, first, count);
      gl.bindVertexArray(null);
    }
  }

  function resize() {
    const r = root.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(r.width * dpr)), h = Math.max(1, Math.round(r.height * dpr));
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
      dirty = true;
    }
  }
  function frame() {
    resize();
    if (dirty) draw();
    requestAnimationFrame(frame);
  }

  // ---- UI ----
  let activeImg = null;
  function setOverlay(url) {
    activeImg = url;
    if (url) {
      overlay.src = url;
      overlay.style.display = "block";
    } else {
      overlay.style.display = "none";
    }
    renderImageButtons();
  }
  const info = document.createElement("div");
  info.className = "row";
  info.textContent = S.note + " Drag: orbit · right/shift-drag: pan · wheel: zoom · W/A/S/D/Q/E: fly · T: trajectories.";
  const camRow = document.createElement("div");
  camRow.className = "row";
  const imgRow = document.createElement("div");
  imgRow.className = "row";
  ui.append(info, document.createElement("br"), camRow, document.createElement("br"), imgRow);
  let current = null;
  function goTo(c) {
    current = c;
    view = { R: c.R.slice(), C: centre(c.R, c.t), K: c };
    target = null;
    setOverlay(null);
    for (const b of camRow.querySelectorAll("button")) b.classList.toggle("on", b.dataset.name === c.name);
    dirty = true;
  }
  function renderImageButtons() {
    imgRow.replaceChildren();
    if (!current || !current.images.length) {
      imgRow.style.display = "none";
      return;
    }
    imgRow.style.display = "inline-block";
    const opts = [[current.kind === "train" ? "ours (live)" : "live", null]].concat(current.images);
    for (const [label, url] of opts) {
      const b = document.createElement("button");
      b.textContent = label;
      if (url === activeImg) b.classList.add("on");
      b.onclick = () => setOverlay(url);
      imgRow.appendChild(b);
    }
  }
  for (const [kind, label] of [["train", "training (mid-exposure)"], ["held-out", "held-out"]]) {
    const cams = S.cameras.filter((c) => c.kind === kind);
    if (!cams.length) continue;
    camRow.appendChild(document.createTextNode(" " + label + ": "));
    for (const c of cams) {
      const b = document.createElement("button");
      b.textContent = c.name;
      b.dataset.name = c.name;
      b.onclick = () => goTo(c);
      camRow.appendChild(b);
    }
  }
  const trajBtn = document.createElement("button");
  trajBtn.textContent = "trajectories";
  trajBtn.onclick = () => { showTraj = !showTraj; trajBtn.classList.toggle("on", showTraj); dirty = true; };
  trajBtn.classList.toggle("on", showTraj);
  if (strips.length) camRow.appendChild(trajBtn);

  function leaveClean() {
    if (clean) {
      clean = false;
      root.classList.remove("clean");
    }
  }
  function moved() {
    if (activeImg) setOverlay(null);
    dirty = true;
  }
  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey };
    canvas.setPointerCapture(e.pointerId);
    canvas.focus();
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    leaveClean();
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX;
    drag.y = e.clientY;
    const dist = orbitDistance();
    if (drag.pan) {
      const k = dist / intrinsics(canvas.width, canvas.height)[0] * (window.devicePixelRatio || 1);
      const off = add(add([0, 0, 0], row(view.R, 0), -dx * k), row(view.R, 1), -dy * k);
      view.C = add(view.C, off, 1);
      target = add(target, off, 1);
    } else {
      // Orbit about the target: turn about the camera's y axis (yaw) and x axis (pitch).
      const rot = mul(axisAngle([0, 1, 0], -dx * 0.005), axisAngle([1, 0, 0], dy * 0.005));
      view.R = mul(rot, view.R);
      view.C = add(target, row(view.R, 2), -dist);
    }
    moved();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    leaveClean();
    const dist = orbitDistance();
    const nd = dist * Math.exp(e.deltaY * 0.001);
    view.C = add(target, row(view.R, 2), -nd);
    moved();
  }, { passive: false });
  canvas.addEventListener("keydown", (e) => {
    leaveClean();
    const step = 0.05 * orbitDistance();
    const dirs = { w: [2, 1], s: [2, -1], d: [0, 1], a: [0, -1], e: [1, -1], q: [1, 1] };
    const k = e.key.toLowerCase();
    if (dirs[k]) {
      const off = add([0, 0, 0], row(view.R, dirs[k][0]), dirs[k][1] * step);
      view.C = add(view.C, off, 1);
      target = add(target, off, 1);
      moved();
    } else if (k === "t") {
      trajBtn.click();
    }
  });

  const start = S.cameras.find((c) => c.name === startCam) || S.cameras[0];
  if (start) goTo(start);
  resize();
  draw();
  // For measurements: the time from navigation start until the first frame is drawn (reading
  // one pixel waits for the GPU).
  gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
  root.dataset.firstFrameMs = performance.now().toFixed(1);
  // Redraw at once on a resize (headless screenshots resize the window just before capture,
  // with no animation frame in between).
  window.addEventListener("resize", () => {
    resize();
    if (dirty) draw();
  });
  requestAnimationFrame(frame);
})();
