// ---- the mask brush: paint or erase features on the source image ------------------------
// The mask lives in a canvas of the texture's size (white: feature). A stroke paints along
// where the pointer's positions come from in the source; when it ends, the mask goes to the
// server (which solves with it from then on, and writes it on Save and Export).
function setupMask(image) {
  const [w, h] = app.info.texture, m = app.mask;
  m.canvas = document.createElement("canvas"); m.canvas.width = w; m.canvas.height = h;
  m.ctx = m.canvas.getContext("2d");
  m.ctx.fillStyle = "#000"; m.ctx.fillRect(0, 0, w, h);
  m.ctx.drawImage(image, 0, 0, w, h);
  m.versions = new Map(); m.version = 0; m.dirty = true;
}

function startStroke(e) {
  const m = app.mask, at = inverse(toWorld(e));
  if (!m.versions.has(m.version)) m.versions.set(m.version, m.canvas.toDataURL("image/png"));
  m.stroke = { last: at, before: current(), painted: false };
  if (at) paint(at, at);
}

function moveStroke(e) {
  const at = inverse(toWorld(e)), s = app.mask.stroke;
  if (at) paint(s.last || at, at);
  s.last = at;
  scheduleDraw();
}

function paint(from, to) {  // a round line of the brush's size (image pixels) between two source points
  const m = app.mask, k = app.info.texture[0] / app.info.width;
  m.ctx.strokeStyle = app.tool === "erase" ? "#000" : "#fff";
  m.ctx.lineWidth = Math.max(1, m.size * k); m.ctx.lineCap = "round";
  m.ctx.beginPath(); m.ctx.moveTo((from[0] + 0.5) * k, (from[1] + 0.5) * k); m.ctx.lineTo((to[0] + 0.5) * k, (to[1] + 0.5) * k);
  m.ctx.stroke();
  m.dirty = true; m.stroke.painted = true;
}

function endStroke() {
  const m = app.mask, s = m.stroke;
  m.stroke = null;
  if (!s.painted) return;
  remember(s.before);
  m.version = Math.max(...m.versions.keys(), m.version) + 1;
  m.versions.set(m.version, m.canvas.toDataURL("image/png"));
  sendMask();
}

function sendMask() {       // the next solve waits for the server to have the mask
  const png = app.mask.canvas.toDataURL("image/png");
  app.maskPosting = fetch(url("/mask"), { method: "POST", headers: { "Content-Type": "application/json" },
                                          body: JSON.stringify({ png }) })
    .then(async (r) => {
      const data = await r.json(); if (!r.ok) throw new Error(data.error);
      app.maskCoverage = data.coverage; app.maskVersion = Math.max(app.maskVersion, data.version);
    })
    .catch((err) => setStatus(failure(err), true, true));
  app.epoch++; requestSolve();
}

function restoreMask(version) {     // undo or redo across a stroke
  const m = app.mask, data = m.versions.get(version);
  m.version = version;
  if (!data) return;
  app.maskPosting = loadImage(data).then((img) => {
    m.ctx.globalCompositeOperation = "copy"; m.ctx.drawImage(img, 0, 0); m.ctx.globalCompositeOperation = "source-over";
    m.dirty = true; scheduleDraw();
    sendMask();
  });
}
