// ---- WebGL: the image on the solved mesh; at most one redraw per animation frame ---------
const glCanvas = $("gl"), overlay = $("overlay"), ctx = overlay.getContext("2d");
const gl = glCanvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false }) ||
           glCanvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: false });
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
const textures = [];

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
  for (const name of ["pos", "uv", "tris", "edges"]) buffers[name] = gl.createBuffer();
}

function setMesh() {        // the grid's texture coordinates and triangles (again after a density change)
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.uv); gl.bufferData(gl.ARRAY_BUFFER, app.uv, gl.STATIC_DRAW);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.tris);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, app.tris, gl.STATIC_DRAW);
  app.edges = null;
}

function texture(unit, source) {
  if (!textures[unit]) textures[unit] = gl.createTexture();
  gl.activeTexture(gl.TEXTURE0 + unit); gl.bindTexture(gl.TEXTURE_2D, textures[unit]);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, source);
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
                        [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]])
    gl.texParameteri(gl.TEXTURE_2D, k, v);
}

function loadImage(path) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img); img.onerror = () => reject(new Error("cannot load " + path));
    img.src = path.startsWith("data:") ? path : url(path);
  });
}

// Everything that changes the picture asks for a frame; the frame draws once, however many asked.
function scheduleDraw(mesh = true) {
  if (mesh) app.glDirty = true;
  if (app.frameRequested) return;
  app.frameRequested = true;
  requestAnimationFrame(() => { app.frameRequested = false; app.frames++; draw(); });
}

function draw() {
  if (!program || !app.positions) return;
  app.draws++;
  const dpr = window.devicePixelRatio || 1, w = overlay.clientWidth, h = overlay.clientHeight;
  for (const c of [glCanvas, overlay]) {
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr); c.height = Math.round(h * dpr); app.glDirty = true;
    }
  }
  if (app.glDirty) drawMesh(w, h);
  drawOverlay(dpr);
}

function drawMesh(w, h) {
  app.glDirty = false; app.glDraws++;
  if (app.mask.dirty) { texture(1, app.mask.canvas); app.mask.dirty = false; }
  gl.viewport(0, 0, glCanvas.width, glCanvas.height);
  gl.clearColor(0.23, 0.23, 0.23, 1); gl.clear(gl.COLOR_BUFFER_BIT);
  const v = app.view;
  gl.uniform4f(gl.getUniformLocation(program, "view"), 2 * v.scale / w, -2 * v.scale / h, 2 * v.ox / w - 1, 1 - 2 * v.oy / h);
  gl.uniform1i(gl.getUniformLocation(program, "image"), 0);
  gl.uniform1i(gl.getUniformLocation(program, "mask"), 1);
  gl.uniform1f(gl.getUniformLocation(program, "tint"), $("mask").checked || app.tool !== "handles" ? 1 : 0);
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.pos); gl.bufferData(gl.ARRAY_BUFFER, app.positions, gl.DYNAMIC_DRAW);
  bindAttribute("pos", buffers.pos); bindAttribute("uv", buffers.uv);
  const line = gl.getUniformLocation(program, "line");
  gl.uniform4f(line, 0, 0, 0, 0);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.tris);
  gl.drawElements(gl.TRIANGLES, app.tris.length, gl.UNSIGNED_INT, 0);
  if ($("grid").checked) {
    const edges = gridLines();
    gl.uniform4f(line, 0.1, 0.9, 1.0, 0.5);
    gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.edges);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, edges, gl.DYNAMIC_DRAW);
    gl.drawElements(gl.LINES, edges.length, gl.UNSIGNED_INT, 0);
    gl.disable(gl.BLEND);
  }
}

function gridLines() {      // rows and columns of the grid, every k-th so lines stay >= 12 px apart on screen
  const cell = app.info.width / (app.nx - 1) * app.view.scale, k = Math.max(1, Math.ceil(12 / cell));
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

// ---- the map on the page: source <-> deformed ------------------------------------------
function nodeAt(i, j) { return j * app.nx + i; }
function shown(node) { return [app.positions[2 * node], app.positions[2 * node + 1]]; }
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

function identity() {
  const p = new Float32Array(app.uv.length);
  for (let i = 0; i < p.length; i += 2) { p[i] = app.uv[i] * app.info.width - 0.5; p[i + 1] = app.uv[i + 1] * app.info.height - 0.5; }
  return p;
}
