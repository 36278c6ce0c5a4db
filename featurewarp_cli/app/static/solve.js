// ---- solving: at most one request in flight; the newest handles win -----------------------
// Every request carries (client, seq). While one is in flight, further edits only mark the
// handles pending; when the answer comes, one request goes with the handles as they are
// then. An answer is dropped when an edit other than a drag (undo, delete, a new handle, a
// mask stroke, a density) came after its request, or when the server says a newer one
// overtook it ("stale"). A request late by BUSY_MS shows the busy state.
function mode() { return $("aware").checked ? $("mode").value : "plain"; }

function held() {
  const h = app.handles, distinct = new Set(h.points.map((p) => p.from.join(","))).size;
  return distinct + 2 * h.curves.length + (h.border === "pinned" ? 4 : typeof h.border === "object" ? 2 * Object.keys(h.border).length : 0);
}

function payload() {        // the handles as the file holds them (version 2 once a handle has an angle)
  const version = app.handles.points.some((p) => p.angle !== undefined) ? 2 : 1;
  return { ...app.handles, version };
}

function requestSolve() {
  scheduleDraw(false);
  app.pending = true;
  if (!app.busy) pump();
}

async function pump() {
  app.busy = true;
  try {
    while (app.pending) { app.pending = false; await solveOnce(); }
  } finally {
    app.busy = false; showLate(false);
  }
}

async function solveOnce() {
  while (app.maskPosting) { const posting = app.maskPosting; await posting; if (app.maskPosting === posting) app.maskPosting = null; }
  if (held() < 2) {
    app.positions = identity(); app.status = null;
    setStatus(app.handles.points.length ? "add a second handle (a pin counts) to deform" : "click to add a handle");
    app.solves++; return scheduleDraw();
  }
  const seq = ++app.seq, epoch = app.epoch, started = performance.now();
  const body = { handles: payload(), mode: mode(), seq, client: app.client, drag: !!(app.drag && app.drag.moved) || !!app.turning };
  app.inFlight++; app.maxInFlight = Math.max(app.maxInFlight, app.inFlight);
  const late = setTimeout(() => showLate(true), BUSY_MS);
  let response, buffer;
  try {
    response = await fetch(url("/solve"), { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
    buffer = response.ok ? await response.arrayBuffer() : null;
  } catch (err) {
    app.solves++; return setStatus(String(err), true);
  } finally {
    app.inFlight--; clearTimeout(late);
  }
  app.solves++;
  if (!response.ok) {
    const err = await response.json().catch(() => ({ error: response.statusText }));
    return setStatus(err.error, true);
  }
  const n = new DataView(buffer).getUint32(0, true);
  const status = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n)));
  if (status.stale || epoch !== app.epoch || seq < app.shown || app.tris.length === 0) { app.dropped++; return; }
  const positions = new Float32Array(buffer.slice(4 + n + ((4 - ((4 + n) % 4)) % 4)));
  if (positions.length !== app.uv.length) { app.dropped++; return; }     // a density change overtook it
  app.shown = seq; app.positions = positions; app.status = status;
  app.lastLatency = performance.now() - started;
  growView();
  const kept = mode() === "plain" ? "plain map (mask ignored)" : `features kept ${status.kept}/${status.components}`;
  setStatus(`solve ${status.ms} ms · folds ${status.folds} · ${kept} · canvas ${status.canvas.join("x")}` +
            (status.warnings.length ? " · " + status.warnings[0] : ""), false);
  scheduleDraw();
}

function showLate(late) {   // the busy state: an answer is late
  if (app.late === late) return;
  app.late = late;
  document.body.classList.toggle("busy", late);
  $("busy").hidden = !late;
}

function setStatus(text, error) {      // the full text also as the tooltip (the line is cut to one)
  const status = $("status");
  status.textContent = text; status.title = text; status.className = error ? "error" : "";
}

async function post(path, body) {
  const response = await fetch(url(path), { method: "POST", headers: { "Content-Type": "application/json" },
                                             body: JSON.stringify(body || { handles: payload(), mode: mode() }) });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error);
  return data;
}

function download(name, blob) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob); a.download = name; a.click();
}

$("save").addEventListener("click", async () => {
  try {
    const data = await post("/save");
    app.saved = data;
    const saved = [data.saved, data.mask_saved].filter(Boolean);
    if (!data.saved) download("handles.json", new Blob([JSON.stringify(data.handles, null, 2)], { type: "application/json" }));
    if (data.mask_png) download("mask.png", await (await fetch("data:image/png;base64," + data.mask_png)).blob());
    setStatus(saved.length ? "saved " + saved.join(" and ") :
              "downloaded handles.json (start with --handles H.json to save in place)");
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

$("density").addEventListener("change", async () => {   // a new preview mesh: the server refactors
  try {
    const info = await post("/density", { density: $("density").value });
    await loadGrid(info);
    app.epoch++; requestSolve();
  } catch (err) { setStatus(err.message, true); }
});
