// ---- controls and start -------------------------------------------------------------------
$("undo").addEventListener("click", undo);
$("redo").addEventListener("click", redo);
$("delete").addEventListener("click", () => remove(app.selected));
$("fit").addEventListener("click", resetView);
for (const id of ["aware", "mode"]) $(id).addEventListener("change", () => { app.epoch++; requestSolve(); });
for (const id of ["grid", "mask"]) $(id).addEventListener("change", () => scheduleDraw());
$("pinborder").addEventListener("change", () => {
  remember();
  app.handles.border = $("pinborder").checked ? "pinned" : "free"; requestSolve();
});
$("canvasmode").addEventListener("change", () => { remember(); app.handles.canvas = $("canvasmode").value; requestSolve(); });
$("tool").addEventListener("change", () => {
  app.tool = $("tool").value; overlay.classList.toggle("brush", app.tool !== "handles"); scheduleDraw();
});
$("brush").addEventListener("input", () => { app.mask.size = Number($("brush").value); scheduleDraw(false); });
window.addEventListener("resize", () => { if (!app.view.user) fitView(); scheduleDraw(); });

function syncControls() {
  $("pinborder").checked = app.handles.border === "pinned";
  $("canvasmode").value = app.handles.canvas || "fit";
}

async function loadGrid(info) {     // the preview mesh of the server's density
  const grid = await fetch(url("/grid")).then((r) => r.arrayBuffer());
  app.info = info;
  const head = new Uint32Array(grid, 0, 4), nodes = head[0], triangles = head[1];
  app.nx = head[2]; app.ny = head[3];
  app.uv = new Float32Array(grid, 16, 2 * nodes);
  app.tris = new Uint32Array(grid, 16 + 8 * nodes, 3 * triangles);
  setMesh();
  app.positions = identity(); app.status = null;
  $("density").value = info.density;
  scheduleDraw();
}

async function start() {
  if (!gl) return setStatus("this browser has no WebGL", true);
  const [info, image, mask] = await Promise.all([
    fetch(url("/state")).then((r) => r.json()), loadImage("/image"), loadImage("/mask")]);
  app.handles = Object.assign({ version: 1, points: [], curves: [], border: "free", canvas: "fit" }, info.handles);
  if (!info.export_to) {
    $("export").disabled = true;
    $("export").title = "start the editor with -o OUT to export";
  }
  $("mode").value = info.mode === "rigid" ? "rigid" : "similarity";
  $("aware").checked = info.mode !== "plain";
  $("mask").checked = info.has_mask;
  $("brush").value = app.mask.size;
  syncControls();
  setupGL();
  await loadGrid(info);
  const margin = 0.15 * Math.max(info.width, info.height);
  Object.assign(app.view, { x0: -margin, y0: -margin, x1: info.width + margin, y1: info.height + margin });
  fitView();
  texture(0, image); setupMask(mask);
  app.maskVersion = info.versions.mask; app.savedAs = current();     // what is on disk: nothing unsaved yet
  if (info.warnings.length) notice("loaded with warnings: " + info.warnings.join(" · "), true);
  document.body.dataset.ready = "1";
  requestSolve();
}

$("notice").addEventListener("click", () => { $("notice").hidden = true; });
start().catch((err) => setStatus(failure(err), true, true));
