// ---- view: world (input pixels) <-> screen (CSS pixels); zoom, pan and pinch ---------------
function fitView() {        // the region x0..x1, y0..y1 fills the stage (unless the user zoomed or panned)
  const v = app.view, w = overlay.clientWidth, h = overlay.clientHeight;
  v.scale = Math.min(w / (v.x1 - v.x0), h / (v.y1 - v.y0));
  v.ox = (w - v.scale * (v.x1 - v.x0)) / 2 - v.scale * v.x0;
  v.oy = (h - v.scale * (v.y1 - v.y0)) / 2 - v.scale * v.y0;
}
const toScreen = (p) => [p[0] * app.view.scale + app.view.ox, p[1] * app.view.scale + app.view.oy];
const onStage = (e) => { const r = overlay.getBoundingClientRect(); return [e.clientX - r.left, e.clientY - r.top]; };
const toWorld = (e) => { const [x, y] = onStage(e); return [(x - app.view.ox) / app.view.scale, (y - app.view.oy) / app.view.scale]; };

function growView() {      // keep the whole deformed image in view (never shrink while editing);
  // while a handle is dragged the view stays put (the pointer keeps its place on the image), and
  // fits once the gesture has ended
  const v = app.view, p = app.positions;
  let grown = !!v.refit;
  for (let i = 0; i < p.length; i += 2) {
    if (p[i] < v.x0) { v.x0 = p[i] - 20; grown = true; } if (p[i] > v.x1) { v.x1 = p[i] + 20; grown = true; }
    if (p[i + 1] < v.y0) { v.y0 = p[i + 1] - 20; grown = true; } if (p[i + 1] > v.y1) { v.y1 = p[i + 1] + 20; grown = true; }
  }
  const gesture = app.drag || app.turning || app.drawing || app.box;
  v.refit = grown && !v.user && !!gesture;
  if (grown && !v.user && !gesture) fitView();
}

function zoomAt(x, y, factor) {     // zoom by factor around the screen point (x, y)
  const v = app.view, scale = Math.min(64, Math.max(0.02, v.scale * factor));
  v.ox = x - (x - v.ox) * scale / v.scale; v.oy = y - (y - v.oy) * scale / v.scale;
  v.scale = scale; v.user = true;
  scheduleDraw();
}

function panBy(dx, dy) { app.view.ox += dx; app.view.oy += dy; app.view.user = true; scheduleDraw(); }

function resetView() { app.view.user = false; fitView(); scheduleDraw(); }

overlay.addEventListener("wheel", (e) => {      // the wheel zooms; a trackpad pinch comes as a wheel with Ctrl
  e.preventDefault();
  const step = e.deltaMode === 1 ? 40 * e.deltaY : e.deltaMode === 2 ? 800 * e.deltaY : e.deltaY;
  const [x, y] = onStage(e);
  zoomAt(x, y, Math.exp(-step * (e.ctrlKey ? 0.01 : 0.0015)));
}, { passive: false });

// Pan: space-drag or middle-drag. Pinch: two fingers zoom and pan.
const touches = new Map();

function startPan(e) { app.panning = { at: onStage(e) }; overlay.style.cursor = "grabbing"; }

function movePan(e) {
  const at = onStage(e), last = app.panning.at;
  app.panning.at = at; panBy(at[0] - last[0], at[1] - last[1]);
}

function endPan() { app.panning = null; overlay.style.cursor = app.space ? "grab" : ""; }

function touchDown(e) {     // true when this finger is the second: a pinch starts, editing stops
  if (e.pointerType !== "touch") return false;
  touches.set(e.pointerId, onStage(e));
  if (touches.size < 2) return false;
  cancelGesture();
  app.pinch = pinchOf();
  return true;
}

function pinchOf() {
  const [a, b] = [...touches.values()];
  return { mid: [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2], span: Math.hypot(a[0] - b[0], a[1] - b[1]) || 1 };
}

function touchMove(e) {     // true while pinching
  if (!touches.has(e.pointerId)) return false;
  touches.set(e.pointerId, onStage(e));
  if (!app.pinch || touches.size < 2) return false;
  const now = pinchOf(), was = app.pinch;
  panBy(now.mid[0] - was.mid[0], now.mid[1] - was.mid[1]);
  zoomAt(now.mid[0], now.mid[1], now.span / was.span);
  app.pinch = now;
  return true;
}

function touchUp(e) {       // true when a pinch ended
  touches.delete(e.pointerId);
  if (!app.pinch) return false;
  if (touches.size < 2) app.pinch = null;
  return true;
}
