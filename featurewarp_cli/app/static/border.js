// ---- the border: eight markers (corners and side middles), each side editable on its own ---
// Markers: 0 TL, 1 T, 2 TR, 3 R, 4 BR, 5 B, 6 BL, 7 L. A side runs left to right (top,
// bottom) or top to bottom (left, right), as in the handles file.
const SIDES = { top: [0, 1, 2], right: [2, 3, 4], bottom: [6, 5, 4], left: [0, 7, 6] };

function markerSides(index) { return Object.keys(SIDES).filter((side) => SIDES[side].includes(index)); }

function markers() {        // where the markers are: on the sides the handles give, else where the solve put them
  const mx = Math.floor((app.nx - 1) / 2), my = Math.floor((app.ny - 1) / 2), X = app.nx - 1, Y = app.ny - 1;
  const m = [[0, 0], [mx, 0], [X, 0], [X, my], [X, Y], [mx, Y], [0, Y], [0, my]].map(([i, j]) => shown(nodeAt(i, j)));
  const b = app.handles.border;
  if (b && typeof b === "object") {
    for (const side of Object.keys(SIDES)) {
      if (!b[side]) continue;
      const line = sideCurve(b[side]), middle = Array.isArray(b[side]) ? pointAlong(line, 0.5) : line[16];
      SIDES[side].forEach((k, j) => { m[k] = j === 1 ? middle : line[j ? line.length - 1 : 0]; });
    }
  }
  return m;
}

function sideCurve(spec) {  // a side of the file as a polyline (a Bezier flattened: point 16 is its middle)
  if (Array.isArray(spec)) return spec;
  const [a, b, c, d] = spec.bezier, line = [];
  for (let k = 0; k <= 32; k++) {
    const t = k / 32, s = 1 - t, w = [s * s * s, 3 * t * s * s, 3 * t * t * s, t * t * t];
    line.push([0, 1].map((i) => w[0] * a[i] + w[1] * b[i] + w[2] * c[i] + w[3] * d[i]));
  }
  return line;
}

function sideThrough(a, m, b) {     // the cubic Bezier from a to b through m at its middle
  const c = [0, 1].map((i) => round3((8 * m[i] - a[i] - b[i]) / 6));
  return { bezier: [a.map(round3), c, c.slice(), b.map(round3)] };
}

function moveMarker(index, p) {     // a corner reshapes its two sides, a middle marker its own side
  const m = markers();
  m[index] = p;
  const b = app.handles.border && typeof app.handles.border === "object" ? app.handles.border : {};
  for (const side of markerSides(index)) {
    const [i, j, k] = SIDES[side];
    b[side] = sideThrough(m[i], m[j], m[k]);
  }
  app.handles.border = b;
  syncControls();
}

function freeSides(index) {         // Delete or Alt-click on a marker: its sides follow the handles again
  const b = app.handles.border;
  if (!b || typeof b !== "object") return;
  for (const side of markerSides(index)) delete b[side];
  if (!Object.keys(b).length) app.handles.border = "free";
}
