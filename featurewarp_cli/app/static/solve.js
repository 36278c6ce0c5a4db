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
    app.solves++; return setStatus(failure(err), true, true);
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
  if (status.versions.grid > app.info.versions.grid || status.versions.mask > app.maskVersion) {
    app.dropped++; return reloadShared(status.versions);      // another window changed the mesh or the mask
  }
  const positions = new Float32Array(buffer.slice(4 + n + ((4 - ((4 + n) % 4)) % 4)));
  if (positions.length !== app.uv.length) { app.dropped++; return; }     // a density change overtook it
  app.shown = seq; app.positions = positions; app.status = status;
  app.lastLatency = performance.now() - started;
  growView();
  const kept = mode() === "plain" ? "plain map (mask ignored)" : `features kept ${status.kept}/${status.components}` +
    (status.provisional ? " in the preview (Export decides)" : "");     // a fold asked, or features eased
  setStatus(`solve ${status.ms} ms · folds ${status.folds} · ${kept} · canvas ${status.canvas.join("x")}` +
            (status.warnings.length ? " · " + status.warnings[0] : ""), false);
  scheduleDraw();
}

async function reloadShared(versions) {     // the server's mesh or mask is another window's: take it
  const info = await fetch(url("/state")).then((r) => r.json()), changed = [];
  if (versions.grid > app.info.versions.grid) { await loadGrid(info); changed.push("the mesh density"); }
  if (versions.mask > app.maskVersion) {
    setupMask(await loadImage("/mask")); app.maskVersion = info.versions.mask; changed.push("the mask");
    $("mask").checked = info.has_mask;
  }
  app.info.versions = info.versions;
  notice(`another window changed ${changed.join(" and ")}: this page reloaded it`);
  app.epoch++; requestSolve();
}

function showLate(late) {   // the busy state: an answer is late (or an Export runs)
  app.late = late;
  const on = app.late || app.exporting;
  document.body.classList.toggle("busy", on);
  $("busy").hidden = !on; $("busy").textContent = app.exporting ? "exporting…" : "solving…";
}

function setStatus(text, error, full) {   // the full text also as the tooltip (the line is cut to one)
  const status = $("status");
  status.textContent = text; status.title = text; status.className = error ? "error" : "";
  if (full) notice(text, error);
}

function notice(text, error) {      // a message read in full (warnings, Export, errors): click hides it
  const box = $("notice");
  box.textContent = text; box.className = error ? "error" : ""; box.hidden = false;
}

const GONE = "the editor's server is not running (restart featurewarp edit)";
function failure(err) { return err instanceof TypeError ? GONE : err.message || String(err); }

async function post(path, body) {   // the answer's JSON; an Error with .confirm when the server asks first
  const response = await fetch(url(path), { method: "POST", headers: { "Content-Type": "application/json" },
                                             body: JSON.stringify(body || { handles: payload(), mode: mode() }) });
  const data = await response.json();
  if (!response.ok) throw Object.assign(new Error(data.error), { confirm: data.confirm });
  return data;
}

async function confirmedPost(path) {    // a write that would drop keys the loaded file had: ask first
  const body = { handles: payload(), mode: mode() };
  try { return await post(path, body); } catch (err) {
    if (!err.confirm || !window.confirm(err.message + "\n\nWrite it anyway?")) throw err;
    return post(path, { ...body, drop_ignored: true });
  }
}

function handlesText(h) {   // one handle per line, as the server writes the file
  const lines = Object.entries(h).map(([key, value]) => {
    const many = value && typeof value === "object" && Object.keys(value).length;
    const inner = !many ? JSON.stringify(value) : Array.isArray(value)
      ? "[\n" + value.map((v) => "    " + JSON.stringify(v)).join(",\n") + "\n  ]"
      : "{\n" + Object.entries(value).map(([k, v]) => `    ${JSON.stringify(k)}: ${JSON.stringify(v)}`).join(",\n") + "\n  }";
    return `  ${JSON.stringify(key)}: ${inner}`;
  });
  return "{\n" + lines.join(",\n") + "\n}\n";
}

const unsaved = () => app.savedAs !== null && current() !== app.savedAs;
window.addEventListener("beforeunload", (e) => { if (unsaved()) { e.preventDefault(); e.returnValue = ""; } });

function download(name, blob) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob); a.download = name; a.click();
}

$("save").addEventListener("click", async () => {
  $("save").blur();                   // Enter or Space afterwards does not save again
  const state = current();
  try {
    const data = await confirmedPost("/save");
    app.saved = data; app.savedAs = state;
    const saved = [data.saved, data.mask_saved].filter(Boolean);
    if (!data.saved) download("handles.json", new Blob([handlesText(data.handles)], { type: "application/json" }));
    if (data.mask_png) download("mask.png", await (await fetch("data:image/png;base64," + data.mask_png)).blob());
    setStatus(saved.length ? "saved " + saved.join(" and ") :
              "downloaded handles.json (start with --handles H.json to save in place)");
  } catch (err) {
    if (!(err instanceof TypeError)) return setStatus(failure(err), true, true);
    download("handles.json", new Blob([handlesText(payload())], { type: "application/json" }));
    app.savedAs = state; app.savedOffline = true;
    setStatus(GONE + ": downloaded handles.json instead" + (app.mask.version ? " (the painted mask is not in it)" : ""),
              true, true);
  }
});

$("export").addEventListener("click", async () => {
  const button = $("export");
  if (app.exporting) return;
  app.exporting = true; button.disabled = true; button.blur(); showLate(app.late);
  setStatus("exporting…");
  const state = current();
  try {
    const data = await confirmedPost("/export");
    app.exported = data; app.exports++;
    if (data.handles_saved === app.info.save_to) app.savedAs = state;
    setStatus(`exported ${data.exported} in ${data.seconds} s (the same bytes as: ${data.command})` +
              data.warnings.map((w) => " · " + w).join(""), false, true);
  } catch (err) { setStatus(failure(err), true, true); } finally {
    app.exporting = false; button.disabled = false; showLate(app.late);
  }
});

$("density").addEventListener("change", async () => {   // a new preview mesh: the server refactors
  try {
    const info = await post("/density", { density: $("density").value });
    await loadGrid(info);
    app.epoch++; requestSolve();
  } catch (err) { setStatus(failure(err), true, true); }
});
