// ---- editing: undo and redo, selection, handles, turning around a pin, the keyboard -------
function current() { return JSON.stringify({ handles: app.handles, mask: app.mask.version }); }

function remember(state) {  // the state before an edit goes on the undo stack; redo starts over
  app.history.push(state || current());
  if (app.history.length > 200) app.history.shift();
  app.future = [];
  app.epoch++;               // answers to requests sent before this edit are dropped
}

function restore(state) {
  const s = JSON.parse(state);
  app.handles = s.handles; app.selected = []; app.epoch++;
  if (s.mask !== app.mask.version) restoreMask(s.mask);
  syncControls(); requestSolve();
}

function undo() { if (app.history.length) { app.future.push(current()); restore(app.history.pop()); } }
function redo() { if (app.future.length) { app.history.push(current()); restore(app.future.pop()); } }

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

function nearPin(p) {       // the point handle within RING screen px of p, not under it (null: none)
  const a = toScreen(p);
  let best = null, bestGap = RING;
  app.handles.points.forEach((q, i) => {
    const b = toScreen(q.to), gap = Math.hypot(a[0] - b[0], a[1] - b[1]);
    if (gap > HIT && gap < bestGap) { best = i; bestGap = gap; }
  });
  return best;
}

function remove(targets) {  // delete handles; a border marker frees its sides
  if (!targets || !targets.length) return;
  remember();
  for (const t of targets.filter((t) => t.kind === "border")) freeSides(t.index);
  for (const kind of ["point", "curve"]) {
    const list = kind === "point" ? app.handles.points : app.handles.curves;
    targets.filter((t) => t.kind === kind).map((t) => t.index).sort((a, b) => b - a).forEach((i) => list.splice(i, 1));
  }
  app.selected = []; syncControls(); requestSolve();
}

function moveSelected(dx, dy) {
  const by = (q) => [round3(q[0] + dx), round3(q[1] + dy)];
  for (const s of app.selected) {
    if (s.kind === "point") app.handles.points[s.index].to = by(app.handles.points[s.index].to);
    else if (s.kind === "curve") app.handles.curves[s.index].to = app.handles.curves[s.index].to.map(by);
  }
}

function startEdit(e) {
  const p = toWorld(e), target = hit(p);
  if (e.altKey) {                                  // Alt: click deletes, drag near a handle turns around it
    if (target) return remove([target]);
    const pin = nearPin(p);
    if (pin !== null) startTurn(pin, p);
    return;
  }
  if (target && e.shiftKey && target.kind !== "border") {
    app.selected = isSelected(target.kind, target.index) ? app.selected.filter((s) => s.kind !== target.kind || s.index !== target.index)
                                                          : app.selected.concat([target]);
    return scheduleDraw(false);
  }
  if (target) {
    if (!isSelected(target.kind, target.index) || target.kind === "border") app.selected = [target];
    app.drag = { last: p, moved: false, before: current(), marker: target.kind === "border" ? target.index : null };
    return scheduleDraw(false);
  }
  if (e.ctrlKey || e.metaKey) { app.box = { from: p, to: p, add: e.shiftKey }; return; }
  if (e.shiftKey) { app.drawing = [p]; return; }
  let from = inverse(p);
  if (!from) { app.selected = []; return scheduleDraw(false); }
  // where the map leaves the clicked point in place, it is a pin (from == to), not the
  // thousandth of a pixel the float32 positions round it to (a 12 MP photo's coordinates)
  if (Math.hypot(from[0] - p[0], from[1] - p[1]) < PIN_SNAP) from = p;
  remember();
  app.handles.points.push({ from: from.map(round3), to: p.map(round3) });
  app.selected = [{ kind: "point", index: app.handles.points.length - 1 }];
  app.drag = { last: p, moved: false, marker: null, created: true };
  requestSolve();
}

function moveEdit(e) {
  const p = toWorld(e);
  if (app.drawing) {
    const last = toScreen(app.drawing[app.drawing.length - 1]), now = toScreen(p);
    if (Math.hypot(now[0] - last[0], now[1] - last[1]) >= 6) { app.drawing.push(p); scheduleDraw(false); }
  } else if (app.box) {
    app.box.to = p; scheduleDraw(false);
  } else if (app.turning) {
    moveTurn(p);
  } else if (app.drag) {
    const d = app.drag, dx = p[0] - d.last[0], dy = p[1] - d.last[1];
    d.last = p;
    if (!d.moved && d.before) remember(d.before);
    d.moved = true;
    if (d.marker !== null) moveMarker(d.marker, p); else moveSelected(dx, dy);
    requestSolve();
  }
}

function endEdit() {
  if (app.drawing) addCurve();
  if (app.box) selectBox();
  const moved = (app.drag && app.drag.moved) || (app.turning && app.turning.moved);
  app.drag = null; app.turning = null;
  if (moved) requestSolve();       // the last answer of a drag is the full one
}

function cancelGesture() {  // a second finger starts a pinch: what the first one began is dropped
  if (app.drag && app.drag.created) undo();
  app.drag = null; app.drawing = null; app.box = null; app.turning = null;
}

function addCurve() {
  const to = app.drawing, from = to.map(inverse);
  app.drawing = null;
  const kept = to.map((p, k) => [p, from[k]]).filter(([, f]) => f);
  if (kept.length < 2) return scheduleDraw(false);
  remember();
  app.handles.curves.push({ from: kept.map(([, f]) => f.map(round3)), to: kept.map(([p]) => p.map(round3)) });
  app.selected = [{ kind: "curve", index: app.handles.curves.length - 1 }];
  requestSolve();
}

function selectBox() {      // the handles inside the box (added to the selection with Shift)
  const { from, to, add } = app.box, inside = (q) =>
    q[0] >= Math.min(from[0], to[0]) && q[0] <= Math.max(from[0], to[0]) && q[1] >= Math.min(from[1], to[1]) && q[1] <= Math.max(from[1], to[1]);
  app.box = null;
  const found = app.handles.points.map((p, i) => inside(p.to) ? { kind: "point", index: i } : null)
    .concat(app.handles.curves.map((c, i) => c.to.some(inside) ? { kind: "curve", index: i } : null)).filter(Boolean);
  app.selected = add ? app.selected.concat(found.filter((f) => !isSelected(f.kind, f.index))) : found;
  scheduleDraw(false);
}

function angleAround(centre, p) { return Math.atan2(p[1] - centre[1], p[0] - centre[0]) * 180 / Math.PI; }

function startTurn(index, p) {
  const point = app.handles.points[index], turns = (app.status && app.status.turns) || [];
  const base = point.angle !== undefined ? point.angle : turns[index] !== undefined ? turns[index] : 0;
  app.turning = { index, base, start: angleAround(point.to, p), before: current(), moved: false };
  app.selected = [{ kind: "point", index }];
  scheduleDraw(false);
}

function moveTurn(p) {
  const t = app.turning, point = app.handles.points[t.index];
  if (!t.moved) { remember(t.before); t.moved = true; }
  let angle = t.base + angleAround(point.to, p) - t.start;
  angle = ((angle + 180) % 360 + 360) % 360 - 180;
  point.angle = Math.round(angle * 10) / 10;
  requestSolve();
}

function nudge(dx, dy) {    // arrow keys: 1 px, with Shift 10 px; a run of presses is one undo step
  if (!app.selected.some((s) => s.kind !== "border")) return;
  const run = () => JSON.stringify(app.selected) + "@" + app.epoch;     // no other edit, the same selection
  if (run() !== app.lastNudge) remember();
  app.lastNudge = run();
  moveSelected(dx, dy); requestSolve();
}

window.addEventListener("keydown", (e) => {
  const key = e.key.toLowerCase(), mod = e.ctrlKey || e.metaKey, field = ["SELECT", "INPUT"].includes(e.target.tagName);
  if (mod && key === "z") { e.preventDefault(); e.shiftKey ? redo() : undo(); }
  else if (mod && key === "y") { e.preventDefault(); redo(); }
  else if (field && e.target.type !== "checkbox") return;
  else if (e.key === "Delete" || e.key === "Backspace") remove(app.selected);
  else if (e.key.startsWith("Arrow")) {
    e.preventDefault();
    const step = e.shiftKey ? 10 : 1, d = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] }[e.key];
    if (d) nudge(d[0] * step, d[1] * step);
  } else if (e.key === " ") { e.preventDefault(); app.space = true; if (!app.panning) overlay.style.cursor = "grab"; }
  else if (e.key === "Escape") { app.selected = []; scheduleDraw(false); }
  else if (e.key === "Alt") { e.preventDefault(); if (app.hover) { app.hover.alt = true; scheduleDraw(false); } }
});

window.addEventListener("keyup", (e) => {
  // Space is the pan key: it does not toggle a focused checkbox nor press a focused button
  if (e.key === " " && (e.target.type === "checkbox" || e.target.tagName === "BUTTON")) e.preventDefault();
  if (e.key === " ") { app.space = false; if (!app.panning) overlay.style.cursor = ""; }
  else if (e.key === "Alt" && app.hover) { app.hover.alt = false; scheduleDraw(false); }
});

// ---- the pointer: one dispatcher for every tool ----------------------------------------
overlay.addEventListener("pointerdown", (e) => {
  if (!app.positions) return;
  try { overlay.setPointerCapture(e.pointerId); } catch (err) { /* a pointer the browser no longer tracks */ }
  if (touchDown(e)) return;
  if (e.button === 1 || (e.button === 0 && app.space)) { e.preventDefault(); return startPan(e); }
  if (e.button !== 0) return;
  if (app.tool !== "handles") return startStroke(e);
  startEdit(e);
});

overlay.addEventListener("pointermove", (e) => {
  app.hover = { at: toWorld(e), alt: e.altKey };
  if (touchMove(e)) return;
  if (app.panning) return movePan(e);
  if (app.mask.stroke) return moveStroke(e);
  moveEdit(e);
  if (app.tool !== "handles" || e.altKey || app.turning) scheduleDraw(false);
});

for (const kind of ["pointerup", "pointercancel"]) {
  overlay.addEventListener(kind, (e) => {
    if (touchUp(e)) return;
    if (app.panning) return endPan();
    if (app.mask.stroke) return endStroke();
    endEdit();
  });
}
overlay.addEventListener("pointerleave", () => { app.hover = null; scheduleDraw(false); });
overlay.addEventListener("auxclick", (e) => e.preventDefault());
