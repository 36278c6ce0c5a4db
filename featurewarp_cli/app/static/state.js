// featurewarp edit: the page draws the solved mesh with WebGL; the local server solves.
// The scripts (state, render, view, overlay, edit, border, mask, solve, start) are one
// script on the page, run in that order, sharing its scope.
"use strict";

const token = new URLSearchParams(location.search).get("token") || "";
const url = (path) => path + "?token=" + encodeURIComponent(token);
const $ = (id) => document.getElementById(id);
const HIT = 9;            // px on screen: how close a click must be to grab a handle
const RING = 45;          // px on screen: Alt-drag this near a point handle (not on it) turns around it
const BUSY_MS = 150;      // an answer later than this shows the busy state
const round3 = (x) => Math.round(x * 1000) / 1000;
const PIN_SNAP = 0.02;    // input px: a click this close to where its point comes from adds a pin (from == to)

const app = {
  info: null, nx: 0, ny: 0, uv: null, tris: null, edges: null, positions: null,
  handles: { version: 1, points: [], curves: [], border: "free", canvas: "fit" },
  // editing: undo and redo stacks of states, the selection ({kind, index}), what the pointer does
  history: [], future: [], selected: [], drag: null, drawing: null, box: null, turning: null, panning: null,
  hover: null, space: false, tool: "handles", lastNudge: "",
  // solving: at most one request in flight, the newest handles win, answers to older edits dropped
  busy: false, pending: false, solves: 0, seq: 0, shown: 0, epoch: 0, dropped: 0, inFlight: 0, maxInFlight: 0,
  late: false, client: Math.random().toString(36).slice(2, 12), maskPosting: null,
  status: null, saved: null, exported: null, exports: 0, exporting: false, savedAs: null, maskVersion: 0,
  // drawing: at most one redraw per animation frame; the mesh only when it changed
  frameRequested: false, glDirty: true, frames: 0, draws: 0, glDraws: 0,
  view: { scale: 1, ox: 0, oy: 0, x0: 0, y0: 0, x1: 1, y1: 1, user: false },
  mask: { canvas: null, ctx: null, version: 0, versions: new Map(), dirty: false, stroke: null, size: 20 },
};
window.featurewarp = app;   // for the browser tests

const isSelected = (kind, index) => app.selected.some((s) => s.kind === kind && s.index === index);
