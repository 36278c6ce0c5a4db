// ---- the overlay: handles, selection, the border's markers, where handles ended, tools ----
function drawOverlay(dpr) {
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, overlay.width, overlay.height);
  if (app.handles.border !== "pinned") drawBorder();
  app.handles.curves.forEach((c, i) => {
    ctx.strokeStyle = isSelected("curve", i) ? "#ffd54f" : "#4fc3f7"; ctx.lineWidth = 3;
    polyline(c.to); ctx.stroke();
  });
  drawEnds();
  app.handles.points.forEach((p, i) => {
    const [x, y] = toScreen(p.to), pin = p.from[0] === p.to[0] && p.from[1] === p.to[1];
    ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI);
    ctx.fillStyle = isSelected("point", i) ? "#ffd54f" : pin ? "#e0e0e0" : "#ffeb3b";
    ctx.fill(); ctx.lineWidth = 2; ctx.strokeStyle = "#000"; ctx.stroke();
    if (p.angle !== undefined) {      // a turned handle: a tick shows its angle
      const a = p.angle * Math.PI / 180;
      ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(x + 14 * Math.cos(a), y + 14 * Math.sin(a));
      ctx.strokeStyle = "#000"; ctx.lineWidth = 2; ctx.stroke();
    }
  });
  if (app.drawing) { ctx.strokeStyle = "#4fc3f7"; ctx.lineWidth = 2; polyline(app.drawing); ctx.stroke(); }
  if (app.box) drawBox();
  drawTool();
}

function polyline(points) {
  ctx.beginPath();
  points.forEach((p, k) => { const [x, y] = toScreen(p); k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
}

function drawBorder() {     // sides given in the handles dashed, and the eight markers
  const b = app.handles.border;
  if (b && typeof b === "object") {
    ctx.strokeStyle = "rgba(255,255,255,0.8)"; ctx.lineWidth = 1.5; ctx.setLineDash([6, 4]);
    for (const side of Object.keys(b)) { polyline(sideCurve(b[side])); ctx.stroke(); }
    ctx.setLineDash([]);
  }
  markers().forEach((m, i) => {
    const [x, y] = toScreen(m), given = markerSides(i).some((s) => b && b[s]);
    ctx.fillStyle = isSelected("border", i) ? "#ffd54f" : given ? "#90caf9" : "#fff";
    ctx.strokeStyle = "#000"; ctx.lineWidth = 1; ctx.fillRect(x - 4, y - 4, 8, 8); ctx.strokeRect(x - 4, y - 4, 8, 8);
  });
}

function drawEnds() {       // where a handle ended, if a feature or the border held it: dashed red
  const status = app.status || {}, ends = status.ends || [], curveEnds = status.curve_ends || [];
  ctx.strokeStyle = "#ff5252"; ctx.lineWidth = 2; ctx.setLineDash([4, 3]);
  app.handles.points.forEach((p, i) => {
    if (!ends[i] || Math.hypot(ends[i][0] - p.to[0], ends[i][1] - p.to[1]) < 2) return;
    polyline([ends[i], p.to]); ctx.stroke();
  });
  app.handles.curves.forEach((c, i) => {
    const ended = curveEnds[i];
    if (ended && offTarget(ended, c.to)) { polyline(ended); ctx.stroke(); }
  });
  ctx.setLineDash([]);
}

function offTarget(ended, to) {   // whether a curve ended 2 px or more from its polyline's ends or middle
  const far = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1]) >= 2;
  return far(ended[0], to[0]) || far(ended[ended.length - 1], to[to.length - 1]) ||
         far(ended[Math.floor(ended.length / 2)], pointAlong(to, 0.5));
}

function pointAlong(line, fraction) {      // the point at this fraction of the polyline's length
  const steps = line.slice(1).map((p, k) => Math.hypot(p[0] - line[k][0], p[1] - line[k][1]));
  let left = fraction * steps.reduce((a, b) => a + b, 0);
  for (let k = 0; k < steps.length; k++) {
    if (left <= steps[k] && steps[k] > 0) {
      const t = left / steps[k];
      return [line[k][0] + t * (line[k + 1][0] - line[k][0]), line[k][1] + t * (line[k + 1][1] - line[k][1])];
    }
    left -= steps[k];
  }
  return line[line.length - 1];
}

function drawBox() {
  const [x0, y0] = toScreen(app.box.from), [x1, y1] = toScreen(app.box.to);
  ctx.strokeStyle = "#ffd54f"; ctx.lineWidth = 1; ctx.setLineDash([5, 3]);
  ctx.strokeRect(Math.min(x0, x1), Math.min(y0, y1), Math.abs(x1 - x0), Math.abs(y1 - y0));
  ctx.setLineDash([]);
}

function drawTool() {       // the brush's outline, or the ring to turn around a handle (Alt)
  const hover = app.hover;
  if (!hover) return;
  const [x, y] = toScreen(hover.at);
  if (app.tool !== "handles") {
    ctx.beginPath(); ctx.arc(x, y, app.mask.size / 2 * app.view.scale, 0, 2 * Math.PI);
    ctx.strokeStyle = app.tool === "erase" ? "#90caf9" : "#ff8a80"; ctx.lineWidth = 1.5; ctx.stroke();
    return;
  }
  const index = app.turning ? app.turning.index : hover.alt ? nearPin(hover.at) : null;
  if (index === null) return;
  const [px, py] = toScreen(app.handles.points[index].to);
  ctx.beginPath(); ctx.arc(px, py, RING - 8, 0, 2 * Math.PI);
  ctx.strokeStyle = "#ffd54f"; ctx.lineWidth = 1.5; ctx.setLineDash([3, 3]); ctx.stroke(); ctx.setLineDash([]);
}
