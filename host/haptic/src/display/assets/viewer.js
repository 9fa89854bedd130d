// WebGL viewer of the host display (see host/haptic/src/display/mod.rs for the wire format).
// Plain WebGL, no build step: the organ surface (shaded, tinted by displacement), the tool
// (shaft from the trocar, tip sphere), the force arrow with its magnitude in newtons, and a HUD
// with a scrolling trace of the tool force's magnitude against time (the last TRACE_S seconds,
// so a press and hold shows a viscoelastic scene's relaxation).
"use strict";
(async function main() {
  const params = new URLSearchParams(location.search);
  const showTool = params.get("tool") !== "0";
  const canvas = document.getElementById("view");
  const gl = canvas.getContext("webgl", { antialias: true, preserveDrawingBuffer: true });
  const hudForce = document.getElementById("force");
  const hudStats = document.getElementById("stats");
  const label = document.getElementById("label");
  const traceCanvas = document.getElementById("trace");
  const traceCtx = traceCanvas.getContext("2d");
  if (!gl || !gl.getExtension("OES_element_index_uint")) {
    hudStats.textContent = "WebGL (with 32-bit indices) is not available in this browser";
    return;
  }
  const info = await (await fetch("api/info")).json();
  const meshBuf = await (await fetch("mesh.bin")).arrayBuffer();
  const head = new Uint32Array(meshBuf, 0, 2);
  const nv = head[0], nt = head[1];
  const rest = new Float32Array(meshBuf, 8, 3 * nv);
  const tris = new Uint32Array(meshBuf, 8 + 12 * nv, 3 * nt);
  const pos = new Float32Array(rest);
  const normals = new Float32Array(3 * nv);
  const disp = new Float32Array(nv);

  // ---- small vector / matrix helpers (column-major 4x4) ----
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const len = (a) => Math.sqrt(dot(a, a));
  const norm = (a) => { const l = len(a) || 1; return scale(a, 1 / l); };
  function mul(a, b) {
    const o = new Float32Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
    return o;
  }
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), o = new Float32Array(16);
    o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1;
    o[14] = 2 * far * near / (near - far);
    return o;
  }
  function lookAt(eye, at, up) {
    const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
    return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
      -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
  }
  function invert(m) {
    // Gauss-Jordan on a 4x4 (column-major in, column-major out).
    const a = [], inv = [];
    for (let r = 0; r < 4; r++) { a.push([]); inv.push([]); for (let c = 0; c < 4; c++) { a[r].push(m[c * 4 + r]); inv[r].push(r === c ? 1 : 0); } }
    for (let c = 0; c < 4; c++) {
      let p = c;
      for (let r = c + 1; r < 4; r++) if (Math.abs(a[r][c]) > Math.abs(a[p][c])) p = r;
      [a[c], a[p]] = [a[p], a[c]]; [inv[c], inv[p]] = [inv[p], inv[c]];
      const d = a[c][c];
      for (let k = 0; k < 4; k++) { a[c][k] /= d; inv[c][k] /= d; }
      for (let r = 0; r < 4; r++) if (r !== c) {
        const f = a[r][c];
        for (let k = 0; k < 4; k++) { a[r][k] -= f * a[c][k]; inv[r][k] -= f * inv[c][k]; }
      }
    }
    const o = new Float32Array(16);
    for (let r = 0; r < 4; r++) for (let c = 0; c < 4; c++) o[c * 4 + r] = inv[r][c];
    return o;
  }
  // Model matrix mapping the unit z axis segment [0, 1] to [from, to], radius r.
  function segment(from, to, r) {
    const z = sub(to, from), l = len(z) || 1e-9, zn = scale(z, 1 / l);
    const helper = Math.abs(zn[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
    const x = norm(cross(helper, zn)), y = cross(zn, x);
    return new Float32Array([x[0] * r, x[1] * r, x[2] * r, 0, y[0] * r, y[1] * r, y[2] * r, 0,
      z[0], z[1], z[2], 0, from[0], from[1], from[2], 1]);
  }
  const ball = (c, r) => new Float32Array([r, 0, 0, 0, 0, r, 0, 0, 0, 0, r, 0, c[0], c[1], c[2], 1]);

  // ---- shaders ----
  function program(vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src); gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    return p;
  }
  const prog = program(`
    attribute vec3 aPos; attribute vec3 aNormal; attribute float aDisp;
    uniform mat4 uVP; uniform mat4 uModel;
    varying vec3 vN; varying vec3 vW; varying float vD;
    void main() {
      vec4 w = uModel * vec4(aPos, 1.0);
      vW = w.xyz; vN = mat3(uModel) * aNormal; vD = aDisp;
      gl_Position = uVP * w;
    }`, `
    precision mediump float;
    varying vec3 vN; varying vec3 vW; varying float vD;
    uniform vec3 uColor; uniform vec3 uEye; uniform float uTint;
    void main() {
      vec3 n = normalize(vN);
      vec3 v = normalize(uEye - vW);
      if (dot(n, v) < 0.0) n = -n;
      vec3 l1 = normalize(vec3(0.4, -0.5, 1.0)), l2 = normalize(vec3(-0.6, 0.7, 0.3));
      float d = 0.25 + 0.65 * max(dot(n, l1), 0.0) + 0.25 * max(dot(n, l2), 0.0);
      float s = pow(max(dot(reflect(-l1, n), v), 0.0), 24.0) * 0.35;
      vec3 base = mix(uColor, vec3(1.0, 0.85, 0.2), clamp(vD * uTint, 0.0, 1.0));
      gl_FragColor = vec4(base * d + vec3(s), 1.0);
    }`);
  const loc = {
    pos: gl.getAttribLocation(prog, "aPos"), normal: gl.getAttribLocation(prog, "aNormal"),
    disp: gl.getAttribLocation(prog, "aDisp"), vp: gl.getUniformLocation(prog, "uVP"),
    model: gl.getUniformLocation(prog, "uModel"), color: gl.getUniformLocation(prog, "uColor"),
    eye: gl.getUniformLocation(prog, "uEye"), tint: gl.getUniformLocation(prog, "uTint"),
  };
  function makeMesh(p, n, d, idx, dynamic) {
    const m = { count: idx.length };
    const usage = dynamic ? gl.DYNAMIC_DRAW : gl.STATIC_DRAW;
    for (const [k, data] of [["pos", p], ["normal", n], ["disp", d]]) {
      m[k] = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, m[k]); gl.bufferData(gl.ARRAY_BUFFER, data, usage);
    }
    m.idx = gl.createBuffer(); gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, m.idx);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
    return m;
  }
  function draw(m, model, color, tint) {
    for (const [k, size] of [["pos", 3], ["normal", 3], ["disp", 1]]) {
      gl.bindBuffer(gl.ARRAY_BUFFER, m[k]); gl.enableVertexAttribArray(loc[k]);
      gl.vertexAttribPointer(loc[k], size, gl.FLOAT, false, 0, 0);
    }
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, m.idx);
    gl.uniformMatrix4fv(loc.model, false, model); gl.uniform3fv(loc.color, color);
    gl.uniform1f(loc.tint, tint);
    gl.drawElements(gl.TRIANGLES, m.count, gl.UNSIGNED_INT, 0);
  }
  // Unit cylinder along z in [0, 1], unit sphere, unit cone.
  function lathe(profile, seg) {
    const p = [], n = [], idx = [];
    profile.forEach(([r, z, nr, nz]) => {
      for (let i = 0; i <= seg; i++) {
        const a = 2 * Math.PI * i / seg, c = Math.cos(a), s = Math.sin(a);
        p.push(r * c, r * s, z); n.push(nr * c, nr * s, nz);
      }
    });
    for (let k = 0; k + 1 < profile.length; k++) for (let i = 0; i < seg; i++) {
      const a = k * (seg + 1) + i, b = a + seg + 1;
      idx.push(a, b, a + 1, a + 1, b, b + 1);
    }
    return makeMesh(new Float32Array(p), new Float32Array(n), new Float32Array(p.length / 3), new Uint32Array(idx), false);
  }
  const sphereProfile = [];
  for (let k = 0; k <= 12; k++) { const t = Math.PI * k / 12; sphereProfile.push([Math.sin(t), -Math.cos(t), Math.sin(t), -Math.cos(t)]); }
  const cylinder = lathe([[1, 0, 1, 0], [1, 1, 1, 0]], 16);
  const sphere = lathe(sphereProfile, 16);
  const cone = lathe([[1, 0, 0.7, 0.7], [0, 1, 0.7, 0.7]], 16);

  function computeNormals() {
    normals.fill(0);
    for (let t = 0; t < nt; t++) {
      const a = 3 * tris[3 * t], b = 3 * tris[3 * t + 1], c = 3 * tris[3 * t + 2];
      const ux = pos[b] - pos[a], uy = pos[b + 1] - pos[a + 1], uz = pos[b + 2] - pos[a + 2];
      const vx = pos[c] - pos[a], vy = pos[c + 1] - pos[a + 1], vz = pos[c + 2] - pos[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (const i of [a, b, c]) { normals[i] += nx; normals[i + 1] += ny; normals[i + 2] += nz; }
    }
    for (let i = 0; i < nv; i++) {
      disp[i] = Math.hypot(pos[3 * i] - rest[3 * i], pos[3 * i + 1] - rest[3 * i + 1], pos[3 * i + 2] - rest[3 * i + 2]);
    }
  }
  computeNormals();
  const organ = makeMesh(pos, normals, disp, tris, true);

  // ---- camera ----
  const lo = info.bbox_min, hi = info.bbox_max;
  const centre = scale(add(lo, hi), 0.5);
  const radius = 0.5 * len(sub(hi, lo));
  const cam = { az: -1.25, el: 0.42, dist: 2.4 * radius };
  let vp = null, eye = null;
  // Returns whether the canvas was resized: resizing clears the drawing buffer, so the caller
  // must draw again even when no new frame arrived.
  function camera() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    const resized = canvas.width !== w || canvas.height !== h;
    if (resized) { canvas.width = w; canvas.height = h; }
    eye = add(centre, scale([Math.cos(cam.el) * Math.cos(cam.az), Math.cos(cam.el) * Math.sin(cam.az), Math.sin(cam.el)], cam.dist));
    vp = mul(perspective(0.8, w / Math.max(h, 1), 0.01 * radius, 20 * radius), lookAt(eye, centre, [0, 0, 1]));
    return resized;
  }
  function project(p) {
    const x = vp[0] * p[0] + vp[4] * p[1] + vp[8] * p[2] + vp[12];
    const y = vp[1] * p[0] + vp[5] * p[1] + vp[9] * p[2] + vp[13];
    const w = vp[3] * p[0] + vp[7] * p[1] + vp[11] * p[2] + vp[15];
    return [(x / w * 0.5 + 0.5) * canvas.clientWidth, (0.5 - y / w * 0.5) * canvas.clientHeight];
  }

  camera();

  // ---- force trace: |F| (N) against the device's time, one point per frame ----
  // Time is the frame's device tick times the loop's nominal 1 ms period (the firmware's
  // 1 kHz tick); points older than TRACE_S are dropped, and a tick that goes back (a new
  // session) starts the trace afresh.
  const TRACE_S = 12, TICK_S = 1e-3;
  const trace = [];
  function traceAdd(tick, force) {
    const t = tick * TICK_S;
    if (trace.length && t < trace[trace.length - 1][0]) trace.length = 0;
    trace.push([t, len(force)]);
    while (trace.length && trace[0][0] < t - TRACE_S) trace.shift();
  }
  function traceMax() { return trace.reduce((m, p) => Math.max(m, p[1]), 0); }
  function traceDraw() {
    const w = traceCanvas.width, h = traceCanvas.height, top = 14, bottom = h - 4;
    traceCtx.clearRect(0, 0, w, h);
    // Full scale: 0.05 N or the trace's largest force rounded up to 1-2-5.
    const max = traceMax();
    let full = 0.05;
    for (const step of [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000]) { full = 0.05 * step; if (full >= max) break; }
    traceCtx.strokeStyle = "rgba(255,255,255,0.35)"; traceCtx.lineWidth = 1;
    traceCtx.beginPath(); traceCtx.moveTo(0, bottom + 0.5); traceCtx.lineTo(w, bottom + 0.5); traceCtx.stroke();
    traceCtx.fillStyle = "#cfd3da"; traceCtx.font = "11px monospace";
    traceCtx.fillText(`|F| 0-${full.toPrecision(2)} N, last ${TRACE_S} s`, 2, 10);
    if (trace.length < 2) return;
    const tEnd = trace[trace.length - 1][0];
    const x = (t) => w * (1 - (tEnd - t) / TRACE_S), y = (f) => bottom - (bottom - top) * f / full;
    traceCtx.strokeStyle = "#7fe37f"; traceCtx.lineWidth = 1.5;
    traceCtx.beginPath();
    trace.forEach((p, i) => (i ? traceCtx.lineTo(x(p[0]), y(p[1])) : traceCtx.moveTo(x(p[0]), y(p[1]))));
    traceCtx.stroke();
  }

  // ---- frames ----
  let tipPx = null;
  let frame = null, framesReceived = 0, dirty = true;
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  ws.binaryType = "arraybuffer";
  ws.onmessage = (ev) => {
    if (typeof ev.data === "string") return;
    const b = ev.data, dv = new DataView(b);
    if (dv.getUint32(0, true) !== 0x31524648 || dv.getUint32(52, true) !== nv) return;
    const f = (o) => dv.getFloat32(o, true);
    frame = {
      seq: dv.getUint32(4, true), tick: dv.getUint32(8, true), state: ["disarmed", "armed", "FAULT"][dv.getUint8(12)],
      contacts: dv.getUint8(13), exact: dv.getUint8(14) === 1, tip: [f(16), f(20), f(24)],
      force: [f(28), f(32), f(36)], tickRate: f(40), fps: f(44), jitter: f(48),
    };
    pos.set(new Float32Array(b, 64, 3 * nv));
    tipPx = project(frame.tip);
    traceAdd(frame.tick, frame.force);
    framesReceived++; dirty = true;
  };
  ws.onclose = () => { hudStats.textContent = "disconnected from the host"; };

  // ---- steering: aim at the rest surface under the mouse ----
  let pressDepth = 0.006, pressing = false, orbiting = false, lastMouse = null, lastSent = 0;
  const hover = -0.008;
  function pick(mx, my) {
    const inv = invert(vp);
    const ndc = [2 * mx / canvas.clientWidth - 1, 1 - 2 * my / canvas.clientHeight];
    const un = (z) => {
      const v = [ndc[0], ndc[1], z, 1], o = [0, 0, 0, 0];
      for (let r = 0; r < 4; r++) for (let k = 0; k < 4; k++) o[r] += inv[k * 4 + r] * v[k];
      return [o[0] / o[3], o[1] / o[3], o[2] / o[3]];
    };
    const o = un(-1), d = norm(sub(un(1), o));
    let best = Infinity;
    for (let t = 0; t < nt; t++) {
      const a = 3 * tris[3 * t], b = 3 * tris[3 * t + 1], c = 3 * tris[3 * t + 2];
      const A = [rest[a], rest[a + 1], rest[a + 2]];
      const e1 = sub([rest[b], rest[b + 1], rest[b + 2]], A), e2 = sub([rest[c], rest[c + 1], rest[c + 2]], A);
      const p = cross(d, e2), det = dot(e1, p);
      if (Math.abs(det) < 1e-18) continue;
      const s = sub(o, A), u = dot(s, p) / det;
      if (u < 0 || u > 1) continue;
      const q = cross(s, e1), v = dot(d, q) / det;
      if (v < 0 || u + v > 1) continue;
      const dist = dot(e2, q) / det;
      if (dist > 0 && dist < best) best = dist;
    }
    return best < Infinity ? add(o, scale(d, best)) : null;
  }
  function steer(aim, depth, force) {
    const now = performance.now();
    if (!aim || ws.readyState !== 1 || (!force && now - lastSent < 15)) return;
    lastSent = now;
    ws.send(JSON.stringify({ aim, depth }));
  }
  let lastAim = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("mousedown", (e) => {
    lastMouse = [e.clientX, e.clientY];
    const aim = e.button === 0 && !e.shiftKey ? pick(e.clientX, e.clientY) : null;
    if (aim) { pressing = true; lastAim = aim; steer(aim, pressDepth, true); } else orbiting = true;
  });
  window.addEventListener("mouseup", () => {
    if (pressing && lastAim) steer(lastAim, hover, true);
    pressing = false; orbiting = false;
  });
  canvas.addEventListener("mousemove", (e) => {
    if (orbiting && lastMouse) {
      cam.az -= 0.008 * (e.clientX - lastMouse[0]);
      cam.el = Math.max(-1.5, Math.min(1.5, cam.el + 0.008 * (e.clientY - lastMouse[1])));
      dirty = true;
    } else {
      const aim = pick(e.clientX, e.clientY);
      if (aim) { lastAim = aim; steer(aim, pressing ? pressDepth : hover, false); }
    }
    lastMouse = [e.clientX, e.clientY];
  });
  function setDepth(d) {
    pressDepth = Math.max(0, Math.min(0.02, d));
    if (pressing && lastAim) steer(lastAim, pressDepth, true);
  }
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); setDepth(pressDepth - Math.sign(e.deltaY) * 0.0005); }, { passive: false });
  window.addEventListener("keydown", (e) => {
    if (e.key === "+" || e.key === "=") setDepth(pressDepth + 0.0005);
    if (e.key === "-") setDepth(pressDepth - 0.0005);
  });

  // ---- render ----
  let rendered = 0;
  function render() {
    requestAnimationFrame(render);
    if (camera()) dirty = true;
    if (!dirty) return;
    dirty = false;
    computeNormals();
    for (const [k, data] of [["pos", pos], ["normal", normals], ["disp", disp]]) {
      gl.bindBuffer(gl.ARRAY_BUFFER, organ[k]); gl.bufferSubData(gl.ARRAY_BUFFER, 0, data);
    }
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(0.114, 0.129, 0.153, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(prog);
    gl.uniformMatrix4fv(loc.vp, false, vp); gl.uniform3fv(loc.eye, eye);
    const identity = new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
    draw(organ, identity, [0.66, 0.27, 0.24], 1 / 0.006);
    label.textContent = "";
    if (frame) {
      const F = frame.force, mag = len(F);
      tipPx = project(frame.tip);
      if (showTool) {
        draw(cylinder, segment(info.fulcrum_m, frame.tip, 0.0015), [0.7, 0.72, 0.76], 0);
        draw(sphere, ball(frame.tip, Math.max(info.tip_radius_m, 0.001)), [0.85, 0.86, 0.9], 0);
        if (mag > 1e-3) {
          // 50 mm per newton, at most 0.12 m; thicker than the shaft, which it often runs along.
          const L = Math.min(0.05 * mag, 0.12), dir = scale(F, 1 / mag);
          const shaftEnd = add(frame.tip, scale(dir, 0.75 * L)), end = add(frame.tip, scale(dir, L));
          draw(cylinder, segment(frame.tip, shaftEnd, 0.0024), [0.3, 0.9, 0.35], 0);
          draw(cone, segment(shaftEnd, end, 0.005), [0.3, 0.9, 0.35], 0);
          const px = project(end);
          label.style.left = (px[0] + 8) + "px"; label.style.top = (px[1] - 10) + "px";
          label.textContent = mag.toFixed(2) + " N";
        }
      }
      hudForce.textContent = "force " + mag.toFixed(3) + " N";
      traceDraw();
      hudStats.textContent =
        `contact  ${frame.contacts ? frame.contacts + " nodes" + (frame.exact ? "" : " (columns loading)") : "free"}\n` +
        `state    ${frame.state}\n` +
        `loop     ${frame.tickRate.toFixed(0)} Hz` + (frame.jitter >= 0 ? `, max jitter ${frame.jitter.toFixed(0)} us` : "") + "\n" +
        `display  ${frame.fps.toFixed(0)} fps, ${nv} nodes, ${nt} triangles\n` +
        `depth    ${(pressDepth * 1000).toFixed(1)} mm (wheel)   ${info.mesh}`;
    }
    rendered++;
  }
  requestAnimationFrame(render);
  setInterval(() => {
    if (ws.readyState === 1) {
      ws.send(JSON.stringify({ report: { tag: params.get("tag"), frames: framesReceived, rendered, seq: frame ? frame.seq : null,
        contacts: frame ? frame.contacts : 0, tip_px: tipPx, width: canvas.clientWidth, height: canvas.clientHeight,
        trace: { points: trace.length, span_s: trace.length ? trace[trace.length - 1][0] - trace[0][0] : 0,
          last_n: trace.length ? trace[trace.length - 1][1] : null, max_n: traceMax() } } }));
    }
  }, 250);
})();
