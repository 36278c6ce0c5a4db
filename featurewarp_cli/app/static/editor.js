// featurewarp edit: the page draws the solved mesh with WebGL; the local server solves.
"use strict";

const token = new URLSearchParams(location.search).get("token") || "";
const url = (path) => path + "?token=" + encodeURIComponent(token);
const $ = (id) => document.getElementById(id);
const HIT = 9;            // px on screen: how close a click must be to grab a handle

const app = {
  info: null, nx: 0, ny: 0, uv: null, tris: null, edges: null, positions: null,
  handles: { version: 1, points: [], curves: [], border: "free", canvas: "fit" },
  markers: null,          // 8 border markers (corners and side middles) once the outline is edited
  history: [], selected: null, drag: null, drawing: null,
  busy: false, pending: false, solves: 0, status: null, saved: null, exported: null,
  view: { scale: 1, ox: 0, oy: 0, x0: 0, y0: 0, x1: 1, y1: 1 },
};
window.featurewarp = app;   // for the browser tests

// ---- WebGL ------------------------------------------------------------------------------
const glCanvas = $("gl"), overlay = $("overlay"), ctx = overlay.getContext("2d");
const gl = glCanvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: true }) ||
           glCanvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: true });
if (gl && !(gl instanceof WebGL2RenderingContext)) gl.getExtension("OES_element_index_uint");
const VERTEX = `attribute vec2 pos; attribute vec2 uv; uniform vec4 view; varying vec2 vuv;
  void main() { vuv = uv; gl_Position = vec4(pos * view.xy + view.zw, 0.0, 1.0); }`;
const FRAGMENT = `precision mediump float; varying vec2 vuv; uniform sampler2D image; uniform sampler2D mask;
  uniform float tint; uniform vec4 line;
  void main() {
    if (line.a > 0.0) { gl_FragColor = line; return; }
    vec4 c = texture2D(image, vuv); float m = texture2D(mask, vuv).r * tint;
    gl_FragColor = vec4(mix(c.rgb, vec3(1.0, 0.15, 0.1), 0.4 * m), 1.0);
  }`;
let program, buffers = {};

function shader(kind, source) {
  const s = gl.createShader(kind);
  gl.shaderSource(s, source); gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}

function setupGL() {
  program = gl.createProgram();
  gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT));
  gl.linkProgram(program);
  gl.useProgram(program);
  for (const name of ["pos", "uv"]) buffers[name] = gl.createBuffer();
  buffers.tris = gl.createBuffer(); buffers.edges = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.uv); gl.bufferData(gl.ARRAY_BUFFER, app.uv, gl.STATIC_DRAW);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.tris);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, app.tris, gl.STATIC_DRAW);
}

function texture(unit, img) {
  const t = gl.createTexture();
  gl.activeTexture(gl.TEXTURE0 + unit); gl.bindTexture(gl.TEXTURE_2D, t);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, img);
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
                        [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]])
    gl.texParameteri(gl.TEXTURE_2D, k, v);
}

function loadImage(path) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img); img.onerror = () => reject(new Error("cannot load " + path));
    img.src = url(path);
  });
}

// ---- view: world (input pixels) <-> screen (CSS pixels) --------------------------------
function fitView() {
  const v = app.view, w = overlay.clientWidth, h = overlay.clientHeight;
  v.scale = Math.min(w / (v.x1 - v.x0), h / (v.y1 - v.y0));
  v.ox = (w - v.scale * (v.x1 - v.x0)) / 2 - v.scale * v.x0;
  v.oy = (h - v.scale * (v.y1 - v.y0)) / 2 - v.scale * v.y0;
}
const toScreen = (p) => [p[0] * app.view.scale + app.view.ox, p[1] * app.view.scale + app.view.oy];
const toWorld = (e) => {
  const r = overlay.getBoundingClientRect();
  return [(e.clientX - r.left - app.view.ox) / app.view.scale, (e.clientY - r.top - app.view.oy) / app.view.scale];
};

function growView() {      // keep the whole deformed image in view (never shrink while editing)
  const v = app.view, p = app.positions;
  let grown = false;
  for (let i = 0; i < p.length; i += 2) {
    if (p[i] < v.x0) { v.x0 = p[i] - 20; grown = true; } if (p[i] > v.x1) { v.x1 = p[i] + 20; grown = true; }
    if (p[i + 1] < v.y0) { v.y0 = p[i + 1] - 20; grown = true; } if (p[i + 1] > v.y1) { v.y1 = p[i + 1] + 20; grown = true; }
  }
  if (grown) fitView();
}

// ---- drawing --------------------------------------------------------------------------
function draw() {
  const dpr = window.devicePixelRatio || 1, w = overlay.clientWidth, h = overlay.clientHeight;
  for (const c of [glCanvas, overlay]) {
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr); c.height = Math.round(h * dpr);
    }
  }
  gl.viewport(0, 0, glCanvas.width, glCanvas.height);
  gl.clearColor(0.23, 0.23, 0.23, 1); gl.clear(gl.COLOR_BUFFER_BIT);
  const v = app.view;
  gl.uniform4f(gl.getUniformLocation(program, "view"), 2 * v.scale / w, -2 * v.scale / h, 2 * v.ox / w - 1, 1 - 2 * v.oy / h);
  gl.uniform1i(gl.getUniformLocation(program, "image"), 0);
  gl.uniform1i(gl.getUniformLocation(program, "mask"), 1);
  gl.uniform1f(gl.getUniformLocation(program, "tint"), $("mask").checked ? 1 : 0);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.pos); gl.bufferData(gl.ARRAY_BUFFER, app.positions, gl.DYNAMIC_DRAW);
  bindAttribute("pos", buffers.pos); bindAttribute("uv", buffers.uv);
  const line = gl.getUniformLocation(program, "line");
  gl.uniform4f(line, 0, 0, 0, 0);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.tris);
  gl.drawElements(gl.TRIANGLES, app.tris.length, gl.UNSIGNED_INT, 0);
  if ($("grid").checked) {
    const edges = gridLines();
    gl.uniform4f(line, 0.1, 0.9, 1.0, 0.6);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.edges);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, edges, gl.DYNAMIC_DRAW);
    gl.drawElements(gl.LINES, edges.length, gl.UNSIGNED_INT, 0);
  }
  drawOverlay(dpr);
}

function gridLines() {      // rows and columns of the grid, every k-th so lines stay >= 8 px apart on screen
  const cell = app.info.width / (app.nx - 1) * app.view.scale, k = Math.max(1, Math.ceil(8 / cell));
  if (app.edges && app.edges.step === k) return app.edges;
  const every = (n) => { const at = []; for (let i = 0; i < n; i += k) at.push(i); if (at[at.length - 1] !== n - 1) at.push(n - 1); return at; };
  const lines = [];
  for (const j of every(app.ny)) for (let i = 0; i + 1 < app.nx; i++) lines.push(nodeAt(i, j), nodeAt(i + 1, j));
  for (const i of every(app.nx)) for (let j = 0; j + 1 < app.ny; j++) lines.push(nodeAt(i, j), nodeAt(i, j + 1));
  app.edges = new Uint32Array(lines); app.edges.step = k;
  return app.edges;
}

function bindAttribute(name, buffer) {
  const at = gl.getAttribLocation(program, name);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
  gl.enableVertexAttribArray(at); gl.vertexAttribPointer(at, 2, gl.FLOAT, false, 0, 0);
}

function drawOverlay(dpr) {
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, overlay.width, overlay.height);
  const sel = app.selected;
  if (!app.handles.border || app.handles.border !== "pinned") {
    markers().forEach((m, i) => {
      const [x, y] = toScreen(m);
      ctx.fillStyle = sel && sel.kind === "border" && sel.index === i ? "#ffd54f" : "#fff";
      ctx.strokeStyle = "#000"; ctx.fillRect(x - 4, y - 4, 8, 8); ctx.strokeRect(x - 4, y - 4, 8, 8);
    });
  }
  app.handles.curves.forEach((c, i) => {
    ctx.strokeStyle = sel && sel.kind === "curve" && sel.index === i ? "#ffd54f" : "#4fc3f7"; ctx.lineWidth = 3;
    ctx.beginPath(); c.to.forEach((p, k) => { const [x, y] = toScreen(p); k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.stroke();
  });
  const ends = (app.status && app.status.ends) || [];
  app.handles.points.forEach((p, i) => {       // where a handle ended, if a feature or the border held it
    if (!ends[i] || Math.hypot(ends[i][0] - p.to[0], ends[i][1] - p.to[1]) < 2) return;
    const [x, y] = toScreen(p.to), [ex, ey] = toScreen(ends[i]);
    ctx.strokeStyle = "#ff5252"; ctx.lineWidth = 2; ctx.setLineDash([4, 3]);
    ctx.beginPath(); ctx.moveTo(ex, ey); ctx.lineTo(x, y); ctx.stroke(); ctx.setLineDash([]);
  });
  app.handles.points.forEach((p, i) => {
    const [x, y] = toScreen(p.to), pin = p.from[0] === p.to[0] && p.from[1] === p.to[1];
    ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI);
    ctx.fillStyle = sel && sel.kind === "point" && sel.index === i ? "#ffd54f" : pin ? "#e0e0e0" : "#ffeb3b";
    ctx.fill(); ctx.lineWidth = 2; ctx.strokeStyle = "#000"; ctx.stroke();
  });
  if (app.drawing) {
    ctx.strokeStyle = "#4fc3f7"; ctx.lineWidth = 2; ctx.beginPath();
    app.drawing.forEach((p, k) => { const [x, y] = toScreen(p); k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.stroke();
  }
}

// ---- the map on the page: source <-> deformed ------------------------------------------
function sourceOf(node) { return [app.uv[2 * node] * app.info.width - 0.5, app.uv[2 * node + 1] * app.info.height - 0.5]; }

function inverse(p) {       // the source point shown at world position p (null outside the image)
  const P = app.positions, T = app.tris;
  for (let t = 0; t < T.length; t += 3) {
    const a = T[t], b = T[t + 1], c = T[t + 2];
    const ax = P[2 * a], ay = P[2 * a + 1], bx = P[2 * b] - ax, by = P[2 * b + 1] - ay;
    const cx = P[2 * c] - ax, cy = P[2 * c + 1] - ay, px = p[0] - ax, py = p[1] - ay;
    const det = bx * cy - by * cx;
    if (det <= 0) continue;
    const u = (px * cy - py * cx) / det, v = (bx * py - by * px) / det;
    if (u >= -1e-6 && v >= -1e-6 && u + v <= 1 + 1e-6) {
      const sa = sourceOf(a), sb = sourceOf(b), sc = sourceOf(c);
      return [sa[0] + u * (sb[0] - sa[0]) + v * (sc[0] - sa[0]), sa[1] + u * (sb[1] - sa[1]) + v * (sc[1] - sa[1])];
    }
  }
  return null;
}

function nodeAt(i, j) { return j * app.nx + i; }
function shown(node) { return [app.positions[2 * node], app.positions[2 * node + 1]]; }

function markers() {        // corners and side middles: TL, T, TR, R, BR, B, BL, L
  if (app.markers) return app.markers;
  const mx = Math.floor((app.nx - 1) / 2), my = Math.floor((app.ny - 1) / 2), X = app.nx - 1, Y = app.ny - 1;
  return [[0, 0], [mx, 0], [X, 0], [X, my], [X, Y], [mx, Y], [0, Y], [0, my]].map(([i, j]) => shown(nodeAt(i, j)));
}

function outline() {
  const m = app.markers;
  return { top: [m[0], m[1], m[2]], right: [m[2], m[3], m[4]], bottom: [m[6], m[5], m[4]], left: [m[0], m[7], m[6]] };
}

// ---- editing --------------------------------------------------------------------------
function snapshot() {
  app.history.push(JSON.stringify({ handles: app.handles, markers: app.markers }));
  if (app.history.length > 200) app.history.shift();
}

function undo() {
  if (!app.history.length) return;
  const s = JSON.parse(app.history.pop());
  app.handles = s.handles; app.markers = s.markers; app.selected = null;
  syncControls(); requestSolve();
}

function hit(p) {
  const near = (q) => { const a = toScreen(p), b = toScreen(q); return Math.hypot(a[0] - b[0], a[1] - b[1]) <= HIT; };
  const points = app.handles.points;
  for (let i = points.length - 1; i >= 0; i--) if (near(points[i].to)) return { kind: "point", index: i };
  for (let i = app.handles.curves.length - 1; i >= 0; i--)
    if (app.handles.curves[i].to.some(near)) return { kind: "curve", index: i };
  if (app.handles.border !== "pinned") {
    const m = markers();
    for (let i = 0; i < m.length; i++) if (near(m[i])) return { kind: "border", index: i };
  }
  return null;
}

function remove(target) {
  if (!target || target.kind === "border") return;
  snapshot();
  (target.kind === "point" ? app.handles.points : app.handles.curves).splice(target.index, 1);
  app.selected = null; requestSolve();
}

overlay.addEventListener("pointerdown", (e) => {
  if (!app.positions) return;
  overlay.setPointerCapture(e.pointerId);
  const p = toWorld(e), target = hit(p);
  if (target && e.altKey) return remove(target);
  if (target) { snapshot(); app.selected = target; app.drag = { ...target, last: p }; return draw(); }
  if (e.shiftKey) { app.drawing = [p]; return; }
  const from = inverse(p);
  if (!from) return;
  snapshot();
  app.handles.points.push({ from: from.map(round3), to: p.map(round3) });
  app.selected = { kind: "point", index: app.handles.points.length - 1 };
  app.drag = { ...app.selected, last: p };
  requestSolve();
});

overlay.addEventListener("pointermove", (e) => {
  const p = toWorld(e);
  if (app.drawing) {
    const last = toScreen(app.drawing[app.drawing.length - 1]), now = toScreen(p);
    if (Math.hypot(now[0] - last[0], now[1] - last[1]) >= 6) { app.drawing.push(p); draw(); }
    return;
  }
  const d = app.drag;
  if (!d) return;
  const dx = p[0] - d.last[0], dy = p[1] - d.last[1];
  d.last = p;
  if (d.kind === "point") app.handles.points[d.index].to = p.map(round3);
  else if (d.kind === "curve") app.handles.curves[d.index].to = app.handles.curves[d.index].to.map((q) => [round3(q[0] + dx), round3(q[1] + dy)]);
  else {
    app.markers = markers().map((q) => q.map(round3));
    app.markers[d.index] = p.map(round3);
    app.handles.border = outline();
  }
  requestSolve();
});

overlay.addEventListener("pointerup", () => {
  if (app.drawing) {
    const to = app.drawing, from = to.map(inverse);
    app.drawing = null;
    const kept = to.map((p, k) => [p, from[k]]).filter(([, f]) => f);
    if (kept.length >= 2) {
      snapshot();
      app.handles.curves.push({ from: kept.map(([, f]) => f.map(round3)), to: kept.map(([p]) => p.map(round3)) });
      app.selected = { kind: "curve", index: app.handles.curves.length - 1 };
      requestSolve();
    } else draw();
  }
  app.drag = null;
});

const round3 = (x) => Math.round(x * 1000) / 1000;

window.addEventListener("keydown", (e) => {
  if ((e.ctrlKey || e.metaKey) && e.key === "z") { e.preventDefault(); undo(); }
  else if (e.key === "Delete" || e.key === "Backspace") remove(app.selected);
});

// ---- solving --------------------------------------------------------------------------
function mode() { return $("aware").checked ? $("mode").value : "plain"; }

function held() {
  const h = app.handles, distinct = new Set(h.points.map((p) => p.from.join(","))).size;
  return distinct + 2 * h.curves.length + (h.border === "pinned" ? 4 : typeof h.border === "object" ? 8 : 0);
}

function requestSolve() {
  draw();
  if (app.busy) { app.pending = true; return; }
  app.busy = true;
  (async () => {
    do { app.pending = false; await solveOnce(); } while (app.pending);
    app.busy = false;
  })();
}

async function solveOnce() {
  if (held() < 2) {
    app.positions = identity(); app.status = null;
    setStatus(app.handles.points.length ? "add a second handle (a pin counts) to deform" : "click to add a handle");
    app.solves++; return draw();
  }
  const response = await fetch(url("/solve"), { method: "POST", headers: { "Content-Type": "application/json" },
                                                 body: JSON.stringify({ handles: app.handles, mode: mode() }) });
  if (!response.ok) {
    const err = await response.json().catch(() => ({ error: response.statusText }));
    app.solves++; return setStatus(err.error, true);
  }
  const buffer = await response.arrayBuffer();
  const n = new DataView(buffer).getUint32(0, true);
  const status = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n)));
  app.positions = new Float32Array(buffer.slice(4 + n + ((4 - ((4 + n) % 4)) % 4)));
  app.status = status; app.solves++;
  growView();
  const kept = mode() === "plain" ? "plain map (mask ignored)" : `features kept ${status.kept}/${status.components}`;
  setStatus(`solve ${status.ms} ms · folds ${status.folds} · ${kept} · canvas ${status.canvas.join("x")}` +
            (status.warnings.length ? " · " + status.warnings[0] : ""), false);
  draw();
}

function identity() {
  const p = new Float32Array(app.uv.length);
  for (let i = 0; i < p.length; i += 2) { p[i] = app.uv[i] * app.info.width - 0.5; p[i + 1] = app.uv[i + 1] * app.info.height - 0.5; }
  return p;
}

function setStatus(text, error) { $("status").textContent = text; $("status").className = error ? "error" : ""; }

async function post(path) {
  const response = await fetch(url(path), { method: "POST", headers: { "Content-Type": "application/json" },
                                             body: JSON.stringify({ handles: app.handles, mode: mode() }) });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error);
  return data;
}

$("save").addEventListener("click", async () => {
  try {
    const data = await post("/save");
    app.saved = data;
    if (data.saved) setStatus("saved " + data.saved);
    else {                  // no --handles file was named: the browser downloads it
      const a = document.createElement("a");
      a.href = URL.createObjectURL(new Blob([JSON.stringify(data.handles, null, 2)], { type: "application/json" }));
      a.download = "handles.json"; a.click();
      setStatus("downloaded handles.json (start with --handles H.json to save in place)");
    }
  } catch (err) { setStatus(err.message, true); }
});

$("export").addEventListener("click", async () => {
  setStatus("exporting…");
  try {
    const data = await post("/export");
    app.exported = data;
    setStatus(`exported ${data.exported} in ${data.seconds} s (the same bytes as: ${data.command})` +
              (data.warnings.length ? " · " + data.warnings[0] : ""));
  } catch (err) { setStatus(err.message, true); }
});

$("undo").addEventListener("click", undo);
$("delete").addEventListener("click", () => remove(app.selected));
for (const id of ["aware", "mode"]) $(id).addEventListener("change", requestSolve);
for (const id of ["grid", "mask"]) $(id).addEventListener("change", draw);
$("pinborder").addEventListener("change", () => {
  snapshot(); app.markers = null;
  app.handles.border = $("pinborder").checked ? "pinned" : "free"; requestSolve();
});
$("canvasmode").addEventListener("change", () => { snapshot(); app.handles.canvas = $("canvasmode").value; requestSolve(); });
window.addEventListener("resize", () => { fitView(); draw(); });

function syncControls() {
  $("pinborder").checked = app.handles.border === "pinned";
  $("canvasmode").value = app.handles.canvas || "fit";
}

// ---- start ------------------------------------------------------------------------------
async function start() {
  if (!gl) return setStatus("this browser has no WebGL", true);
  const [info, grid, image, mask] = await Promise.all([
    fetch(url("/state")).then((r) => r.json()), fetch(url("/grid")).then((r) => r.arrayBuffer()),
    loadImage("/image"), loadImage("/mask")]);
  app.info = info;
  const head = new Uint32Array(grid, 0, 4);
  const nodes = head[0], triangles = head[1];
  app.nx = head[2]; app.ny = head[3];
  app.uv = new Float32Array(grid, 16, 2 * nodes);
  app.tris = new Uint32Array(grid, 16 + 8 * nodes, 3 * triangles);
  app.handles = Object.assign({ version: 1, points: [], curves: [], border: "free", canvas: "fit" }, info.handles);
  if (typeof app.handles.border === "object") {
    const b = app.handles.border;
    if (b.top && b.right && b.bottom && b.left && [b.top, b.right, b.bottom, b.left].every((s) => s.length === 3))
      app.markers = [b.top[0], b.top[1], b.top[2], b.right[1], b.right[2], b.bottom[1], b.bottom[0], b.left[1]];
  }
  if (!info.export_to) {
    $("export").disabled = true;
    $("export").title = "start the editor with -o OUT to export";
  }
  $("mode").value = info.mode === "rigid" ? "rigid" : "similarity";
  $("aware").checked = info.mode !== "plain";
  $("mask").checked = info.has_mask;
  syncControls();
  const margin = 0.15 * Math.max(info.width, info.height);
  Object.assign(app.view, { x0: -margin, y0: -margin, x1: info.width + margin, y1: info.height + margin });
  fitView();
  setupGL(); texture(0, image); texture(1, mask);
  app.positions = identity();
  document.body.dataset.ready = "1";
  requestSolve();
}

start().catch((err) => setStatus(String(err), true));
