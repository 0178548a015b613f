// homocal ui: the page. Plain JavaScript and canvas; every computation but the site map's scale and origin
// (pixels <-> metres, to place a click) is a call to the local server's JSON API (homocal/ui/api.py), which runs
// the library. Image pixels follow OpenCV (pixel centres at integers); a view maps image (or map) pixel p to
// canvas pixel (p + 0.5) * zoom + pan.
"use strict";

const CORNERS = ["TL", "TR", "BR", "BL"];
const HANDLE_PX = 9;  // grab radius of corners and points, canvas pixels
const $ = (id) => document.getElementById(id);

const S = {
  info: null,
  trap: { image: [], map: [] },
  points: [],          // {u, v, x, y}; x, y null until its ground position is given
  camera: [0, 0],
  mode: "trapezoid",
  view: null,          // last /api/view answer
  fit: null,           // last /api/fit answer, null when out of date
  fitStale: null,      // the previous fit's summary, shown struck through
  probe: null,         // {u, v, answer}
  watch: null,         // last /api/watch answer (the horizon over time), null when out of date
  lines: [[]],         // the line tool's polylines ([u, v] frame px), the last one being clicked
  lens: null,          // last /api/lens or /api/checkerboard answer: the lens fitted, which the server now uses
  at: null,            // the time (s) picked on the time plot: a fit from boxes is that stretch's correction
  message: null,       // {text, kind: "error" | "warn" | "info", topic}: the status line (see say)
};
const images = { frame: new Image(), map: new Image() };
const views = { frame: { zoom: 1, panX: 0, panY: 0 }, map: { zoom: 1, panX: 0, panY: 0 } };

// ---- server -----------------------------------------------------------------------------------------
let inFlight = 0;  // requests to the server not yet answered
// The per-launch token of the URL the server printed (?token=...): every POST sends it.
const TOKEN = new URLSearchParams(window.location.search).get("token") || "";
async function api(name, body) {
  inFlight++;
  let response, data;
  try {
    response = await fetch("/api/" + name, {
      method: "POST", headers: { "Content-Type": "application/json", "X-Homocal-Token": TOKEN },
      body: JSON.stringify(body),
    });
    data = await response.json();
  } finally { inFlight--; }
  if (!response.ok) {
    const error = new Error(data.error || response.statusText);
    error.status = response.status;
    error.exists = data.exists === true;
    throw error;
  }
  return data;
}

function number(id) { return parseFloat($(id).value); }

function viewRequest() {
  return {
    trapezoid: { image: S.trap.image, map: S.trap.map }, camera_origin: S.camera,
    click_sigma_px: number("click-sigma"), point_sigma_px: number("point-sigma"), map_sigma_px: number("map-sigma"),
    tolerance_m: number("tolerance"),
  };
}

function fromBoxes(method) { return S.info.box_methods.includes(method); }

function fitRequest() {
  const req = { ...viewRequest(), points: S.points.map((p) => [p.u, p.v, p.x, p.y]), method: $("method").value };
  for (const key of S.info.settings[req.method]) {  // a setting's field has the setting's name as its id
    if ($(key) && $(key).value !== "") req[key] = number(key);
  }
  if (fromBoxes(req.method) && S.at !== null) req.at_s = S.at;  // the stretch picked on the time plot
  return fromBoxes(req.method) ? { ...req, ...boxRequest() } : req;
}

// The session's boxes file: the page names a detector of it, never a path; the pedestrian settings' fields.
function boxRequest() {
  const req = {};
  if (S.info.boxes.detectors.length) req.detector = $("detector").value;
  for (const s of S.info.box_settings) {
    if (s.choices) req[s.name] = $(s.id).value === "auto" ? "auto" : $(s.id).value === "yes";  // yes, no or auto
    else if (s.low === null) req[s.name] = $(s.id).checked;  // yes or no
    else if ($(s.id).value !== "") req[s.name] = number(s.id);
  }
  return req;
}

// ---- status line: one message at a time, tied to its topic ("view", "fit", "probe", "click", "files"); it is
// cleared when its cause is gone: a new answer on the same topic, or (fit, files) any change of the fit's inputs.
function say(text, kind, topic) {
  S.message = text ? { text, kind, topic } : null;
  showMessage();
}
function clearTopic(...topics) {
  if (S.message && topics.includes(S.message.topic)) say("");
}
function showMessage() {
  const m = $("message"), msg = S.message;
  m.textContent = msg ? msg.text : "";
  m.title = m.textContent;  // the whole text on hover if it is longer than the fixed-height line shows
  m.className = msg ? msg.kind : "";
}

let viewSeq = 0, viewShown = 0;  // the newest answer shown wins over older ones that arrive late
// Ask for the overlays of the current trapezoid; light: without the error bars (while dragging: they are the
// slow part). Resolves to null if the server accepted it, else to its message.
async function refreshView(light) {
  const seq = ++viewSeq;
  let error = null, answer = null;
  try { answer = await api("view", { ...viewRequest(), errorbars: !light }); } catch (e) { error = e.message; }
  if (seq > viewShown) {
    viewShown = seq;
    S.view = answer;
    if (error) say(error, "error", "view");
    else clearTopic("view");
    render();
  }
  return error;
}

let dragBusy = false, dragAgain = false;
function dragView() {  // at most one light request in flight while a corner is dragged
  if (dragBusy) { dragAgain = true; return; }
  dragBusy = true;
  // Once the corner is let go, the full refresh of onUp shows the final trapezoid: no light request after it.
  refreshView(true).finally(() => { dragBusy = false; if (dragAgain) { dragAgain = false; if (drag) dragView(); } });
}

function invalidateFit() {
  if (S.fit) S.fitStale = S.fit.summary;
  S.fit = null;
  clearTopic("fit", "files");  // what they said was of the inputs before this change
}

// A change of the trapezoid; undo() takes it back if the server refuses it (mirrored map, bad order...).
function invalidateWatch() { S.watch = null; S.at = null; }  // its inputs changed: the trapezoid, the boxes' settings

async function changeTrapezoid(undo) {
  invalidateFit(); invalidateWatch();
  S.probe = null;
  render();
  const reason = await refreshView();
  if (reason && undo) {
    undo();
    await refreshView();
    say("refused: " + reason, "error", "view");
  }
}

// ---- views: zoom, pan, coordinates ------------------------------------------------------------------
function fitView(name) {
  const c = $(name), img = images[name], v = views[name];
  v.zoom = Math.min(c.width / img.naturalWidth, c.height / img.naturalHeight);
  v.panX = (c.width - img.naturalWidth * v.zoom) / 2;
  v.panY = (c.height - img.naturalHeight * v.zoom) / 2;
}
function toScreen(name, p) { const v = views[name]; return [(p[0] + 0.5) * v.zoom + v.panX, (p[1] + 0.5) * v.zoom + v.panY]; }
function toPixel(name, x, y) { const v = views[name]; return [(x - v.panX) / v.zoom - 0.5, (y - v.panY) / v.zoom - 0.5]; }
function mapToGround(p) {  // site-map pixels -> ground metres (data_schema.md: px = ox + s x, py = oy - s y)
  const m = S.info.map;
  return [(p[0] - m.origin_px[0]) / m.scale_px_per_m, (m.origin_px[1] - p[1]) / m.scale_px_per_m];
}
function groundToMap(g) {
  const m = S.info.map;
  return [m.origin_px[0] + g[0] * m.scale_px_per_m, m.origin_px[1] - g[1] * m.scale_px_per_m];
}
const round = (x, step) => Math.round(x / step) / Math.round(1 / step);  // step: 0.1 or 0.01

// ---- drawing ----------------------------------------------------------------------------------------
// Each render records what it drew on window.homocalUI.drawn (labels placed and hidden, ellipses, boxes): what
// the browser tests check, and where a new overlay records its own.
const LABEL_FONT = "bold 12px sans-serif", LABEL_HEIGHT = 12;
// Where a label may go, tried in this order: (dx, dy) of its baseline's start from its anchor (negative dx: the
// text ends dx left of it); the farther ones get a leader line to the anchor.
const LABEL_OFFSETS = [[8, -8], [-8, -8], [8, 20], [-8, 20], [16, -24], [-16, -24], [16, 36], [-16, 36], [0, -40], [0, 52]];
const LEADER_PX = 22;
let drawn = null;  // {frame: {...}, map: {...}} of the last render (newDrawn)

function newDrawn() {
  const one = () => ({ pending: [], taken: [], labels: [], hidden: [], ellipses: [], boxes: { used: 0, outlier: 0, border: 0, hidden: 0 } });
  return { frame: one(), map: one(), plot: { people: 0, moves: [], band: 0, references: [], refused: [] } };
}

function polyline(ctx, name, pts, close) {
  ctx.beginPath();
  pts.forEach((p, i) => { const s = toScreen(name, p); i ? ctx.lineTo(s[0], s[1]) : ctx.moveTo(s[0], s[1]); });
  if (close) ctx.closePath();
  ctx.stroke();
}
function style(ctx, color, width, dash) { ctx.strokeStyle = color; ctx.lineWidth = width; ctx.setLineDash(dash || []); }

// A label to place once everything is drawn (placeLabels): near one of its anchors (image or map pixels), the
// higher priority first; one that finds no free spot is left out (drawn[name].hidden).
function label(name, anchors, text, color, priority) {
  drawn[name].pending.push({ anchors: anchors.map((p) => toScreen(name, p)), text, color, priority });
}
// Points along an image (or map) line where a label of it may go: at the given shares of the frame's width.
function alongLine(segment, shares) {
  const [[u0, v0], [u1, v1]] = segment, W = S.info.frame.width;
  return shares.map((k) => { const u = k * W; return [u, v0 + (v1 - v0) * (u - u0) / (u1 - u0)]; });
}
function alongPolyline(line, shares) { return shares.map((k) => line[Math.floor(k * (line.length - 1))]); }
function longest(lines) { return lines.reduce((a, b) => (b.length > a.length ? b : a), []); }

const overlaps = (a, b) => a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;

function placeLabels(ctx, name) {
  const c = $(name), d = drawn[name];
  ctx.font = LABEL_FONT; ctx.setLineDash([]);
  d.pending.sort((a, b) => b.priority - a.priority).forEach((l) => {
    const w = ctx.measureText(l.text).width;
    for (const a of l.anchors) {
      for (const [dx, dy] of LABEL_OFFSETS) {
        const x = dx >= 0 ? a[0] + dx : a[0] + dx - w, y = a[1] + dy;  // the baseline's start
        const box = { x: x - 1, y: y - LABEL_HEIGHT, w: w + 2, h: LABEL_HEIGHT + 3 };
        if (box.x < 0 || box.y < 0 || box.x + box.w > c.width || box.y + box.h > c.height) continue;
        if (d.taken.some((t) => overlaps(t, box))) continue;
        if (Math.hypot(dx, dy) > LEADER_PX) {
          style(ctx, l.color, 1);
          ctx.beginPath(); ctx.moveTo(a[0], a[1]);
          ctx.lineTo(Math.min(Math.max(a[0], box.x), box.x + box.w), Math.min(Math.max(a[1], box.y), box.y + box.h)); ctx.stroke();
        }
        ctx.lineWidth = 3; ctx.strokeStyle = "rgba(0,0,0,0.8)"; ctx.strokeText(l.text, x, y);
        ctx.fillStyle = l.color; ctx.fillText(l.text, x, y);
        d.taken.push(box); d.labels.push({ text: l.text, ...box });
        return;
      }
    }
    d.hidden.push(l.text);
  });
  d.pending = [];
}

// A filled marker; it also keeps labels off itself.
function dot(ctx, name, p, r, color, fill) {
  const s = toScreen(name, p);
  ctx.beginPath(); ctx.arc(s[0], s[1], r, 0, 2 * Math.PI);
  ctx.setLineDash([]);
  if (fill) { ctx.fillStyle = color; ctx.fill(); }
  ctx.strokeStyle = fill ? "#000" : color; ctx.lineWidth = 2; ctx.stroke();
  drawn[name].taken.push({ x: s[0] - r - 1, y: s[1] - r - 1, w: 2 * r + 2, h: 2 * r + 2 });
}
function scaled(poly, centre, k) { return poly.map((p) => [centre[0] + k * (p[0] - centre[0]), centre[1] + k * (p[1] - centre[1])]); }

function drawGrid(ctx, grid, colors) {
  style(ctx, colors[0], 1); grid.minor.forEach((l) => polyline(ctx, "frame", l));
  style(ctx, colors[1], 1.6); grid.major.forEach((l) => polyline(ctx, "frame", l));
  style(ctx, colors[2], 1.6, [6, 4]);
  grid.rings.forEach((ring) => ring.lines.forEach((l) => polyline(ctx, "frame", l)));
}

// The 1-sigma ellipses of error_bars' answer (the server leaves out those beyond the trustworthy range).
function drawEllipses(ctx, name, bars, key, centres, color, kind) {
  const k = number("ellipse-scale") || 1;
  style(ctx, color || "#ff4fd8", 1.6);
  bars[key].forEach((e, i) => {
    polyline(ctx, name, scaled(e, centres[i], k), true);
    drawn[name].ellipses.push({ kind, ground: bars.points[i] });
  });
}

function drawTrapezoid(ctx, name, quad) {
  style(ctx, "#33e0ff", 2);
  if (quad.length > 1) polyline(ctx, name, quad, quad.length === 4);
  quad.forEach((p, i) => { dot(ctx, name, p, 5, "#33e0ff", true); label(name, [p], CORNERS[i], "#33e0ff", 5); });
}

const BOX_STYLES = { used: ["rgba(125,255,107,0.55)", []], outlier: ["#ff3b3b", []], border: ["rgba(200,200,200,0.6)", [3, 3]],
                     hidden: ["#ffb000", [2, 2]] };
// The people's boxes a fit from boxes read, by their part in it (api.drawn_boxes), if "show boxes" is ticked.
function drawBoxes(ctx) {
  const boxes = S.fit && S.fit.boxes;
  if (!boxes || !$("show-boxes").checked) return;
  for (const [kind, [color, dash]] of Object.entries(BOX_STYLES)) {
    style(ctx, color, kind === "outlier" ? 1.5 : 1, dash);
    boxes[kind].forEach((outline) => polyline(ctx, "frame", outline, true));  // the frame's pixels
    drawn.frame.boxes[kind] = boxes[kind].length;
  }
}

// keepTable: leave the reference-point inputs in place (the user is typing in them), only clear its residuals.
function render(keepTable) {
  if (!S.info) return;
  drawn = newDrawn();
  window.homocalUI.drawn = drawn;
  renderFrame();
  renderMap();
  renderPlot();
  renderPanels(keepTable);
  showMessage();
}

function renderFrame() {
  const c = $("frame"), ctx = c.getContext("2d"), v = views.frame;
  ctx.setTransform(1, 0, 0, 1, 0, 0); ctx.clearRect(0, 0, c.width, c.height);
  ctx.setTransform(v.zoom, 0, 0, v.zoom, v.panX + 0.5 * v.zoom, v.panY + 0.5 * v.zoom);
  ctx.drawImage(images.frame, -0.5, -0.5);
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  const view = S.view, corrected = S.fit && $("show-corrected").checked;
  drawBoxes(ctx);
  if (view && view.complete) {
    drawGrid(ctx, view.grid, ["rgba(255,255,255,0.28)", "rgba(255,255,255,0.75)", "rgba(255,235,90,0.9)"]);
    view.grid.rings.forEach((ring) => {
      const line = longest(ring.lines);
      if (line.length) label("frame", alongPolyline(line, [0.5, 0.35, 0.65]), ring.r + " m", "#ffeb5a", 1);
    });
    if (corrected) drawGrid(ctx, S.fit.corrected_grid, ["rgba(255,157,46,0.35)", "rgba(255,157,46,0.9)", "rgba(255,157,46,0.9)"]);
    if (view.horizon) {
      style(ctx, "#ff5050", 2, [10, 6]); polyline(ctx, "frame", view.horizon);
      label("frame", alongLine(view.horizon, [0.02, 0.3, 0.6]), "horizon", "#ff5050", 3);
    }
    if (corrected && S.fit.horizon) {  // the horizon of the mapping the correction maps with
      style(ctx, "#ff9d2e", 2, [4, 4]); polyline(ctx, "frame", S.fit.horizon);
      label("frame", alongLine(S.fit.horizon, [0.15, 0.45, 0.75]), "fitted horizon", "#ff9d2e", 3);
    }
    if (view.errorbars) {
      drawEllipses(ctx, "frame", view.errorbars, "image", view.errorbars.image_points, null, "view");
      style(ctx, "#ff4fd8", 2.5, [4, 4]);
      view.errorbars.trustworthy_image.forEach((l) => polyline(ctx, "frame", l));
      const ring = longest(view.errorbars.trustworthy_image);
      if (ring.length) label("frame", alongPolyline(ring, [0.3, 0.5, 0.7]), "trustworthy", "#ff4fd8", 2);
    }
  }
  S.lines.forEach((line, i) => {  // the line tool's polylines
    if (!line.length) return;
    style(ctx, "#b8ff3b", 1.5, [3, 3]); polyline(ctx, "frame", line);
    line.forEach((p) => dot(ctx, "frame", p, 3, "#b8ff3b", true));
    label("frame", [line[0]], "L" + i, "#b8ff3b", 4);
  });
  drawTrapezoid(ctx, "frame", S.trap.image);
  S.points.forEach((p, i) => { dot(ctx, "frame", [p.u, p.v], 5, "#7dff6b", true); label("frame", [[p.u, p.v]], "P" + i, "#7dff6b", 4); });
  if (S.probe) {
    dot(ctx, "frame", [S.probe.u, S.probe.v], 4, "#ff4fd8", true);
    const bars = S.probe.answer.errorbars;
    if (bars) drawEllipses(ctx, "frame", bars, "image", bars.image_points, null, "probe");
  }
  placeLabels(ctx, "frame");
}

function renderMap() {
  const c = $("map"), ctx = c.getContext("2d"), v = views.map, m = S.info.map;
  ctx.setTransform(1, 0, 0, 1, 0, 0); ctx.clearRect(0, 0, c.width, c.height);
  ctx.setTransform(v.zoom, 0, 0, v.zoom, v.panX + 0.5 * v.zoom, v.panY + 0.5 * v.zoom);
  ctx.drawImage(images.map, -0.5, -0.5);
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  const view = S.view;
  const cam = groundToMap(S.camera), s = m.scale_px_per_m * v.zoom, camS = toScreen("map", cam);
  if (view && view.complete) {
    ctx.save();  // the footprint reaches far beyond the map: clip it to the map image
    const tl = toScreen("map", [-0.5, -0.5]);
    ctx.beginPath(); ctx.rect(tl[0], tl[1], m.width * v.zoom, m.height * v.zoom); ctx.clip();
    ctx.fillStyle = "rgba(51,224,255,0.16)";
    ctx.beginPath();
    view.footprint.forEach((p, i) => { const q = toScreen("map", p); i ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]); });
    ctx.closePath(); ctx.fill();
    style(ctx, "rgba(51,224,255,0.8)", 1.5); ctx.stroke();
    ctx.restore();
    view.grid.rings.forEach((ring) => {
      style(ctx, "rgba(255,235,90,0.8)", 1.2, [6, 4]);
      ctx.beginPath(); ctx.arc(camS[0], camS[1], ring.r * s, 0, 2 * Math.PI); ctx.stroke();
      const at = (deg) => [cam[0] + ring.r * m.scale_px_per_m * Math.sin(deg * Math.PI / 180),
                           cam[1] - ring.r * m.scale_px_per_m * Math.cos(deg * Math.PI / 180)];
      label("map", [at(0), at(-30), at(30)], ring.r + " m", "#ffeb5a", 1);
    });
    if (view.errorbars) {
      drawEllipses(ctx, "map", view.errorbars, "map", view.errorbars.points.map(groundToMap), null, "view");
      const r = view.errorbars.trustworthy_range_m;
      if (r !== null) {
        style(ctx, "#ff4fd8", 2.5, [4, 4]);
        ctx.beginPath(); ctx.arc(camS[0], camS[1], r * s, 0, 2 * Math.PI); ctx.stroke();
      }
    }
  }
  dot(ctx, "map", cam, 5, "#ffffff", true); label("map", [cam], "camera", "#ffffff", 4);
  drawTrapezoid(ctx, "map", S.trap.map);
  S.points.forEach((p, i) => {
    if (p.x === null || p.y === null) return;
    const g = groundToMap([p.x, p.y]);
    if (S.fit) {
      const before = groundToMap(S.fit.mapped[i]), after = groundToMap(S.fit.corrected[i]);
      style(ctx, "#ffffff", 1.2); polyline(ctx, "map", [g, before]);
      style(ctx, "#ff9d2e", 1.2); polyline(ctx, "map", [g, after]);
      dot(ctx, "map", before, 3, "#ffffff", true); dot(ctx, "map", after, 3, "#ff9d2e", true);
    }
    dot(ctx, "map", g, 5, "#7dff6b", true); label("map", [g], "P" + i, "#7dff6b", 4);
  });
  if (S.probe) {
    const a = S.probe.answer;
    dot(ctx, "map", groundToMap(a.ground), 4, "#ff4fd8", true);
    if (a.corrected) dot(ctx, "map", groundToMap(a.corrected), 4, "#ff9d2e", true);
    if (a.errorbars) drawEllipses(ctx, "map", a.errorbars, "map", a.errorbars.points.map(groundToMap), null, "probe");
    const own = a.corrected_errorbars;  // the correction's own error model, about the corrected position
    if (own) drawEllipses(ctx, "map", own, "map", own.points.map(groundToMap), "#ff9d2e", "probe");
  }
  placeLabels(ctx, "map");
}

// The horizon over time (/api/watch): time (s) across, the horizon row (px, down as in the image) up the side;
// each person's implied row (dots), the estimate with its 1-sigma band, the detected moves (vertical lines at
// their change points), the clicked horizon and a fitted one (horizontal lines), and each stretch whose correction
// homocal watch refuses shaded red across its time span. Records what it drew in drawn.plot.
const PLOT_MARGIN = { left: 52, right: 10, top: 8, bottom: 20 };
function renderPlot() {
  const w = S.watch;
  $("plot-box").hidden = !w;
  if (!w) return;
  const c = $("timeplot"), r = c.getBoundingClientRect(), ctx = c.getContext("2d"), d = drawn.plot;
  c.width = Math.round(r.width); c.height = Math.round(r.height);
  ctx.clearRect(0, 0, c.width, c.height);
  const fitted = S.fit && S.fit.correction.fitted && S.fit.correction.fitted.horizon_row;
  const refs = [[w.clicked_row, "#ff5050", "clicked"]].concat(typeof fitted === "number" ? [[fitted, "#ff9d2e", "fitted"]] : []);
  const finite = (v) => v !== null && Number.isFinite(v);
  const e = w.estimate, band = e.t.map((t, i) => [t, e.row[i], e.sigma[i]]).filter((p) => finite(p[1]) && finite(p[2]));
  // rows shown: the band and the references, with room around them (people beyond are left out: clipped)
  const rows = band.flatMap(([, v, s]) => [v - s, v + s]).concat(refs.map((x) => x[0]));
  const pad = Math.max(5, (Math.max(...rows) - Math.min(...rows)) * 0.3);
  const lo = Math.min(...rows) - pad, hi = Math.max(...rows) + pad, t1 = Math.max(...w.people.t, 1e-9);
  const X = (t) => PLOT_MARGIN.left + (c.width - PLOT_MARGIN.left - PLOT_MARGIN.right) * t / t1;
  const Y = (v) => PLOT_MARGIN.top + (c.height - PLOT_MARGIN.top - PLOT_MARGIN.bottom) * (v - lo) / (hi - lo);
  ctx.font = "11px sans-serif"; ctx.fillStyle = "#aaa"; ctx.textAlign = "right";
  for (const v of [lo + pad, (lo + hi) / 2, hi - pad]) ctx.fillText(v.toFixed(1), PLOT_MARGIN.left - 4, Y(v) + 4);
  ctx.textAlign = "center";
  for (let k = 0; k <= 4; k++) ctx.fillText((t1 * k / 4).toFixed(0) + (k === 4 ? " s" : ""), X(t1 * k / 4), c.height - 5);
  ctx.textAlign = "left";
  ctx.fillText(`horizon row (px at column ${w.column.toFixed(0)})`, PLOT_MARGIN.left + 4, PLOT_MARGIN.top + 10);
  ctx.save(); ctx.beginPath();
  ctx.rect(PLOT_MARGIN.left, PLOT_MARGIN.top, c.width - PLOT_MARGIN.left - PLOT_MARGIN.right, c.height - PLOT_MARGIN.top - PLOT_MARGIN.bottom);
  ctx.clip();
  w.stretches.forEach((s, i) => {  // a refused stretch: from its start to the next one's (or the end)
    if (!s.refused) return;
    const x0 = X(s.start_s), x1 = X(i + 1 < w.stretches.length ? w.stretches[i + 1].start_s : t1);
    ctx.fillStyle = "rgba(255,80,80,0.18)"; ctx.fillRect(x0, PLOT_MARGIN.top, x1 - x0, c.height - PLOT_MARGIN.top - PLOT_MARGIN.bottom);
    ctx.fillStyle = "#ff5050"; ctx.fillText("refused", x0 + 3, PLOT_MARGIN.top + 24);
    d.refused.push({ start_s: s.start_s, x0, x1 });
  });
  if (band.length) {  // the 1-sigma band, then the estimate
    ctx.fillStyle = "rgba(159,211,255,0.3)"; ctx.beginPath();
    band.forEach(([t, v, s], i) => (i ? ctx.lineTo(X(t), Y(v - s)) : ctx.moveTo(X(t), Y(v - s))));
    band.slice().reverse().forEach(([t, v, s]) => ctx.lineTo(X(t), Y(v + s)));
    ctx.closePath(); ctx.fill();
    style(ctx, "#9fd3ff", 1.5); ctx.beginPath();
    band.forEach(([t, v], i) => (i ? ctx.lineTo(X(t), Y(v)) : ctx.moveTo(X(t), Y(v)))); ctx.stroke();
    d.band = band.length;
  }
  ctx.fillStyle = "rgba(230,230,230,0.8)";
  w.people.t.forEach((t, i) => { ctx.fillRect(X(t) - 1.5, Y(w.people.row[i]) - 1.5, 3, 3); });
  d.people = w.people.t.length;
  for (const [v, color, name] of refs) {
    style(ctx, color, 1.5, [6, 4]); ctx.beginPath(); ctx.moveTo(X(0), Y(v)); ctx.lineTo(X(t1), Y(v)); ctx.stroke();
    d.references.push({ name, y: Y(v) });
  }
  for (const m of w.moves) {
    style(ctx, "#ff4fd8", 2); ctx.beginPath(); ctx.moveTo(X(m.t_s), PLOT_MARGIN.top); ctx.lineTo(X(m.t_s), c.height - PLOT_MARGIN.bottom); ctx.stroke();
    ctx.fillStyle = "#ff4fd8"; ctx.fillText(`move ${m.t_s.toFixed(1)} s`, X(m.t_s) + 3, c.height - PLOT_MARGIN.bottom - 4);
    d.moves.push({ t_s: m.t_s, x: X(m.t_s) });
  }
  if (S.at !== null) {
    style(ctx, "#33e0ff", 2, [4, 3]); ctx.beginPath(); ctx.moveTo(X(S.at), PLOT_MARGIN.top); ctx.lineTo(X(S.at), c.height - PLOT_MARGIN.bottom); ctx.stroke();
    d.at = X(S.at);
  }
  ctx.restore();
  plotTime = (x) => Math.min(Math.max((x - PLOT_MARGIN.left) / (c.width - PLOT_MARGIN.left - PLOT_MARGIN.right), 0), 1) * t1;
}

let plotTime = null;  // canvas x -> time (s) of the last plot drawn
function pickStretch(e) {  // a click on the time plot: the stretch at that time is what a fit from boxes uses
  if (!S.watch || !plotTime) return;
  const w = S.watch, t = plotTime(e.clientX - $("timeplot").getBoundingClientRect().left);
  invalidateFit();
  S.at = t;
  const start = w.stretches.filter((s) => s.start_s <= t).pop() || w.stretches[0];
  $("watch-summary").textContent = w.summary + `\npicked ${t.toFixed(1)} s: ` + (!start ? "no stretch has 3 people yet" :
    `the stretch from ${start.start_s.toFixed(1)} s (horizon row ${start.horizon_row.toFixed(1)} px); ` +
    (start.refused ? `homocal watch refuses its correction: ${start.refused}` : "Fit with pedestrians uses its correction"));
  render();
}

async function doWatch() {
  try {
    S.watch = await api("watch", { ...viewRequest(), ...boxRequest() });
    $("watch-summary").textContent = S.watch.summary;
    clearTopic("watch");
  } catch (e) { S.watch = null; say(e.message, "error", "watch"); }
  render();
}

// ---- panels -----------------------------------------------------------------------------------------
const fmt = (x, d) => (x === null || x === undefined || Number.isNaN(x) ? "-" : x.toFixed(d));

function renderPanels(keepTable) {
  const rows = CORNERS.map((c, i) => {
    const a = S.trap.image[i], b = S.trap.map[i];
    return `<tr><th>${c}</th><td>${a ? fmt(a[0], 1) + ", " + fmt(a[1], 1) : "-"}</td><td>${b ? fmt(b[0], 1) + ", " + fmt(b[1], 1) : "-"}</td></tr>`;
  });
  $("corners-table").innerHTML = "<tr><th></th><th>image px</th><th>map px</th></tr>" + rows.join("");
  const nextImage = S.trap.image.length, nextMap = S.trap.map.length;
  let prompt = "";
  if (S.mode === "trapezoid") {
    const parts = [];
    if (nextImage < 4) parts.push(`click image corner ${CORNERS[nextImage]} (${nextImage + 1} of 4) on the frame`);
    if (nextMap < 4) parts.push(`map corner ${CORNERS[nextMap]} (${nextMap + 1} of 4) on the map`);
    prompt = parts.length ? "Next: " + parts.join(" · ") : "Trapezoid complete: drag a corner to adjust it";
  } else if (S.mode === "reference") {
    const open = S.points.findIndex((p) => p.x === null || p.y === null);
    prompt = open >= 0 ? `P${open}: click its true ground position on the map, or type x, y below`
                       : "Click a reference point's foot on the frame";
  } else if (S.mode === "probe") {
    prompt = "Click any image point: its ground position and error bar";
  } else if (S.mode === "lines") {
    prompt = `Click points along an edge straight in the world (line L${S.lines.length - 1}, 3 or more points); End line for the next`;
  } else {
    prompt = "Click the ground point under the camera on the map";
  }
  $("prompt").textContent = prompt;
  const clicked = S.lines.filter((l) => l.length);
  if (clicked.length) $("lines-count").textContent = `${clicked.length} line${clicked.length === 1 ? "" : "s"}, ` +
    `${clicked.reduce((n, l) => n + l.length, 0)} points`;

  const table = $("points-table");
  if (keepTable) table.querySelectorAll(".residual").forEach((td) => { td.textContent = ""; });
  else table.innerHTML = pointRows();

  const summary = $("fit-summary");
  if (S.fit) { summary.textContent = S.fit.summary; summary.className = worse(S.fit) ? "out worse" : "out"; }
  else if (S.fitStale) { summary.textContent = S.fitStale + "\n(out of date: press Fit)"; summary.className = "out stale"; }
  else summary.textContent = "no fit yet: a complete trapezoid and 3 or more reference points";

  const bars = S.view && S.view.errorbars;
  if (!S.view || !S.view.complete) $("errorbar-summary").textContent = "";
  else if (!bars) $("errorbar-summary").textContent = "error bars: when the corner is let go";
  else {
    const r = bars.trustworthy_range_m;
    $("errorbar-summary").textContent = `trustworthy range (1-sigma error <= ${number("tolerance")} m): ` +
      (r === null ? "unbounded" : r.toFixed(1) + " m") + "  (dashed pink ring)" +
      (bars.beyond ? `\n${bars.beyond} grid nodes beyond it have no ellipse: their 1-sigma error exceeds the tolerance` : "");
  }
  if (S.probe) {
    const a = S.probe.answer, b = a.errorbars;
    $("probe-summary").textContent = `probe (${fmt(S.probe.u, 1)}, ${fmt(S.probe.v, 1)}) px -> ground ` +
      `(${fmt(a.ground[0], 2)}, ${fmt(a.ground[1], 2)}) m at ${fmt(a.distance, 2)} m` +
      (a.corrected ? `; corrected (${fmt(a.corrected[0], 2)}, ${fmt(a.corrected[1], 2)}) m` : "") +
      (b.sigma.length ? `; 1-sigma ellipse ${fmt(b.sigma[0][0], 3)} x ${fmt(b.sigma[0][1], 3)} m` : "; no error bar (at the horizon)") +
      (a.corrected_errorbars && a.corrected_errorbars.sigma.length ?
        `; corrected 1-sigma ellipse ${fmt(a.corrected_errorbars.sigma[0][0], 3)} x ${fmt(a.corrected_errorbars.sigma[0][1], 3)} m` : "");
  }
}

function pointRows() {
  const head = "<tr><th>#</th><th>u</th><th>v</th><th>x</th><th>y</th><th>err before</th><th>after</th><th></th></tr>";
  return head + S.points.map((p, i) => {
    const input = (key, step) => `<input data-i="${i}" data-key="${key}" type="number" step="${step}" value="${p[key] === null ? "" : p[key]}">`;
    const before = S.fit ? fmt(S.fit.residual_before[i], 3) : "", after = S.fit ? fmt(S.fit.residual_after[i], 3) : "";
    return `<tr><th>P${i}</th><td>${input("u", 0.1)}</td><td>${input("v", 0.1)}</td><td>${input("x", 0.01)}</td>` +
           `<td>${input("y", 0.01)}</td><td class="residual">${before}</td><td class="residual">${after}</td><td><button data-del="${i}">x</button></td></tr>`;
  }).join("");
}

// ---- mouse ------------------------------------------------------------------------------------------
function eventPixel(name, e) { const r = $(name).getBoundingClientRect(); return [e.clientX - r.left, e.clientY - r.top]; }

function handleAt(name, sx, sy) {
  const near = (p) => { const s = toScreen(name, p); return Math.hypot(s[0] - sx, s[1] - sy) <= HANDLE_PX; };
  const quad = S.trap[name === "frame" ? "image" : "map"];
  for (let i = 0; i < quad.length; i++) if (near(quad[i])) return { kind: "corner", i };
  for (let i = 0; i < S.points.length; i++) {
    const p = S.points[i];
    if (name === "frame" && near([p.u, p.v])) return { kind: "point", i };
    if (name === "map" && p.x !== null && near(groundToMap([p.x, p.y]))) return { kind: "point", i };
  }
  return null;
}

let drag = null;  // {name, kind: "pan" | "corner" | "point" | "click", i, down, last, moved, start}

function onDown(name, e) {
  e.preventDefault();
  const [sx, sy] = eventPixel(name, e);
  if (e.button === 2 || e.shiftKey) { drag = { name, kind: "pan", last: [sx, sy], moved: false }; return; }
  if (e.button !== 0) return;
  const hit = S.mode === "lines" ? null : handleAt(name, sx, sy);  // a line's point may fall on a corner
  drag = { name, kind: hit ? hit.kind : "click", i: hit ? hit.i : -1, down: [sx, sy], moved: false,
           start: JSON.parse(JSON.stringify({ trap: S.trap, points: S.points })) };
}

function onMove(name, e) {
  const [sx, sy] = eventPixel(name, e);
  const p = toPixel(name, sx, sy);
  $("cursor").textContent = name === "frame" ? `frame u=${p[0].toFixed(1)} v=${p[1].toFixed(1)} px`
    : `map px=${p[0].toFixed(1)} py=${p[1].toFixed(1)} -> x=${mapToGround(p)[0].toFixed(2)} y=${mapToGround(p)[1].toFixed(2)} m`;
  if (!drag || drag.name !== name) return;
  if (drag.kind === "pan") {
    views[name].panX += sx - drag.last[0]; views[name].panY += sy - drag.last[1];
    drag.last = [sx, sy]; drag.moved = true; render(); return;
  }
  if (drag.kind === "click" || Math.hypot(sx - drag.down[0], sy - drag.down[1]) < 2) return;
  drag.moved = true;
  const q = [round(p[0], 0.1), round(p[1], 0.1)];
  if (drag.kind === "corner") {
    S.trap[name === "frame" ? "image" : "map"][drag.i] = q;
    invalidateFit(); dragView();
  } else {
    const pt = S.points[drag.i];
    if (name === "frame") { pt.u = q[0]; pt.v = q[1]; }
    else { const g = mapToGround(p); pt.x = round(g[0], 0.01); pt.y = round(g[1], 0.01); }
    invalidateFit();
  }
  render();
}

async function onUp(name, e) {
  if (!drag || drag.name !== name) return;
  const d = drag;
  drag = null;
  if (d.kind === "corner" && d.moved) {
    await changeTrapezoid(() => { S.trap = d.start.trap; });
  } else if (d.kind === "click") {  // (a click on a corner or point without moving it does nothing)
    const [sx, sy] = eventPixel(name, e);
    const p = toPixel(name, sx, sy);
    await clickAt(name, [round(p[0], 0.1), round(p[1], 0.1)], p);
  }
}

async function clickAt(name, q, exact) {
  if (S.mode === "trapezoid") {
    const quad = S.trap[name === "frame" ? "image" : "map"];
    if (quad.length >= 4) { say(`all 4 ${name === "frame" ? "image" : "map"} corners are placed: drag one to move it, or Clear`, "info", "click"); return; }
    clearTopic("click");
    quad.push(q);
    await changeTrapezoid(() => quad.pop());
  } else if (S.mode === "reference") {
    const open = S.points.find((p) => p.x === null || p.y === null);
    if (name === "frame") S.points.push({ u: q[0], v: q[1], x: null, y: null });
    else if (open) { const g = mapToGround(exact); open.x = round(g[0], 0.01); open.y = round(g[1], 0.01); }
    else { say("click the reference point's foot on the frame first", "error", "click"); return; }
    clearTopic("click");
    invalidateFit(); render();
  } else if (S.mode === "probe") {
    if (name !== "frame") { say("probe: click a point of the frame", "error", "probe"); return; }
    try {
      const answer = await api("locate", { ...viewRequest(), point: q, correction: S.fit ? S.fit.correction : null });
      S.probe = { u: q[0], v: q[1], answer };
      clearTopic("probe");
    } catch (e) { say(e.message, "error", "probe"); }
    render();
  } else if (S.mode === "lines") {
    if (name !== "frame") { say("straight lines: click them on the frame", "error", "click"); return; }
    clearTopic("click", "lens");
    S.lines[S.lines.length - 1].push(q);
    render();
  } else if (name !== "map") {
    say("camera ground point: click it on the map", "error", "click");
  } else {
    clearTopic("click");
    const g = mapToGround(exact);
    S.camera = [round(g[0], 0.01), round(g[1], 0.01)];
    $("camera-x").value = S.camera[0]; $("camera-y").value = S.camera[1];
    await changeTrapezoid(null);
  }
}

function onWheel(name, e) {
  e.preventDefault();
  const [sx, sy] = eventPixel(name, e), v = views[name];
  const k = Math.exp(-e.deltaY * 0.0015);
  v.panX = sx - (sx - v.panX) * k; v.panY = sy - (sy - v.panY) * k; v.zoom *= k;
  render();
}

// ---- buttons ----------------------------------------------------------------------------------------
// A fit that makes its reference (or check) points worse: negative improvement.
function worse(fit) { const k = fit.correction.calibration_improvement; return k !== null && k < 0; }

function fitVerdict(fit) {
  if (worse(fit)) {
    const which = fromBoxes($("method").value) ? "check points" : "reference points";
    return [`${which} ${fmt(fit.error_before, 3)} -> ${fmt(fit.error_after, 3)} m, ` +
            `${fmt(fit.correction.calibration_improvement, 1)} %: ` +
            "this correction makes them worse", "warn"];
  }
  if (fit.warnings.length) return ["warning: " + fit.warnings.join("; "), "warn"];
  return ["fitted: " + fit.summary, "info"];
}

async function doFit() {
  const open = S.points.findIndex((p) => p.x === null || p.y === null);
  if (open >= 0) { say(`P${open} has no ground position yet: click it on the map or type x, y`, "error", "fit"); return; }
  try {
    S.fit = await api("fit", fitRequest());
    S.fitStale = null;
    say(...fitVerdict(S.fit), "fit");
  } catch (e) { S.fit = null; say(e.message, "error", "fit"); }
  render();
}

async function doSave() {
  const request = fitRequest();
  try {
    let answer;
    try { answer = await api("save", request); }
    catch (e) {
      if (!e.exists || !window.confirm(e.message + ". Replace?")) throw e;
      answer = await api("save", { ...request, overwrite: true });
    }
    $("files-summary").textContent = "wrote " + answer.written.join(", ") + "\nsame as: " +
      (answer.lens_command ? answer.lens_command + " && " : "") + answer.command;
    say("saved", "info", "files");
  } catch (e) { say(e.message, "error", "files"); }
}

// Fit the lens (/api/lens from the clicked lines, /api/checkerboard from photographs): the server uses it from
// then on, so the overlays are asked again. request: a function giving the request (it may fail: said as an error).
async function fitLens(endpoint, request, verb) {
  try {
    const answer = await api(endpoint, await request());
    S.lens = answer;
    $("lens-summary").textContent = answer.summary;
    invalidateFit();
    say(`lens ${verb}: ` + answer.summary, "info", "lens");
    await refreshView();
  } catch (e) { say(e.message, "error", "lens"); }
}

const doFitLens = () => fitLens("lens", () => ({ lines: S.lines.filter((l) => l.length), terms: $("lens-terms").value,
                                                 hfov_deg: number("lens-hfov") }), "fitted");

// The chosen photographs as [{name, data: base64}]; an error, before any is read, if their base64 exceeds the
// server's bound on their request (max_board_body: it would refuse them).
async function boardPhotos() {
  const files = [...$("board-photos").files];
  const bytes = files.reduce((n, f) => n + f.size, 0);
  if (4 * Math.ceil(bytes / 3) > S.info.max_board_body) {
    throw new Error(`photos: ${(bytes / 2 ** 20).toFixed(1)} MiB of photographs; the server takes at most ` +
                    `${(S.info.max_board_body * 3 / 4 / 2 ** 20).toFixed(1)} MiB in one request (choose fewer, or smaller files)`);
  }
  return Promise.all(files.map((f) => new Promise((resolve, reject) => {
    const reader = new FileReader();
    reader.onload = () => resolve({ name: f.name, data: reader.result.slice(reader.result.indexOf(",") + 1) });
    reader.onerror = () => reject(new Error(`photos: cannot read ${f.name}`));
    reader.readAsDataURL(f);
  })));
}

const doCalibrate = () => fitLens("checkerboard", async () => ({
  photos: await boardPhotos(), pattern: $("board-pattern").value, square_m: number("board-square"),
  terms: $("lens-terms").value }), "calibrated");

async function doSaveLens() {
  try {
    let answer;
    try { answer = await api("save_lens", {}); }
    catch (e) {
      if (!e.exists || !window.confirm(e.message + ". Replace?")) throw e;
      answer = await api("save_lens", { overwrite: true });
    }
    $("lens-summary").textContent = "wrote " + answer.written.join(", ") + "\nsame as: " + answer.command;
    say("saved", "info", "lens");
  } catch (e) { say(e.message, "error", "lens"); }
}

async function doLoad() {
  try {
    const answer = await api("load", {});
    S.trap = answer.trapezoid;
    S.points = answer.points.map((p) => ({ u: p[0], v: p[1], x: p[2], y: p[3] }));
    S.fit = null; S.fitStale = null; S.probe = null;
    if (answer.fit) {
      $("method").value = answer.fit.method; $("seed").value = answer.fit.seed; $("threshold").value = answer.fit.threshold;
      showMethodFields();
      S.camera = answer.fit.camera_origin;
      $("camera-x").value = S.camera[0]; $("camera-y").value = S.camera[1];
    }
    await refreshView();
    if (answer.fit && (S.points.length >= 3 || fromBoxes(answer.fit.method))) await doFit();
    $("files-summary").textContent = "loaded " + answer.loaded.join(", ");
  } catch (e) { say(e.message, "error", "files"); }
}

function bind() {
  for (const name of ["frame", "map"]) {
    const c = $(name);
    c.addEventListener("mousedown", (e) => onDown(name, e));
    c.addEventListener("mousemove", (e) => onMove(name, e));
    c.addEventListener("wheel", (e) => onWheel(name, e), { passive: false });
    c.addEventListener("contextmenu", (e) => e.preventDefault());
  }
  document.querySelectorAll("input[name=mode]").forEach((r) => r.addEventListener("change", () => {
    S.mode = r.value; clearTopic("click", "probe"); render();
  }));
  $("clear-trapezoid").onclick = () => { S.trap = { image: [], map: [] }; changeTrapezoid(null); };
  $("clear-points").onclick = () => { S.points = []; invalidateFit(); render(); };
  $("fit").onclick = doFit;
  $("watch").onclick = doWatch;
  $("timeplot").addEventListener("click", pickStretch);
  $("fit-lens").onclick = doFitLens;
  $("calibrate").onclick = doCalibrate;
  $("save-lens").onclick = doSaveLens;
  $("end-line").onclick = () => { if (S.lines[S.lines.length - 1].length) S.lines.push([]); render(); };
  $("clear-lines").onclick = () => { S.lines = [[]]; clearTopic("lens"); render(); };
  $("save").onclick = doSave;
  $("load").onclick = doLoad;
  $("points-table").addEventListener("change", (e) => {
    const t = e.target;
    if (!t.dataset.key) return;
    const value = t.value === "" ? null : parseFloat(t.value);
    S.points[+t.dataset.i][t.dataset.key] = value;
    invalidateFit(); render(true);
  });
  $("points-table").addEventListener("click", (e) => {
    if (e.target.dataset.del === undefined) return;
    S.points.splice(+e.target.dataset.del, 1);
    invalidateFit(); render();
  });
  for (const id of ["camera-x", "camera-y"]) {
    $(id).addEventListener("change", () => { S.camera = [number("camera-x"), number("camera-y")]; changeTrapezoid(null); });
  }
  for (const id of ["click-sigma", "point-sigma", "map-sigma", "tolerance"]) $(id).addEventListener("change", () => refreshView());
  $("ellipse-scale").addEventListener("change", () => render());
  $("show-corrected").addEventListener("change", () => render());
  $("show-boxes").addEventListener("change", () => render());
  $("method").addEventListener("change", () => { showMethodFields(); invalidateFit(); render(); });
  for (const id of ["detector", "seed", "threshold"]) {
    $(id).addEventListener("change", () => { invalidateFit(); if (id === "detector") invalidateWatch(); render(); });
  }
  $("use-hand-placed").onclick = () => { S.trap = JSON.parse(JSON.stringify(S.info.dataset.hand_placed)); changeTrapezoid(null); };
  $("use-calibration").onclick = () => {
    S.points = S.info.dataset.calibration.map((p) => ({ u: p[0], v: p[1], x: p[2], y: p[3] }));
    invalidateFit(); render();
  };
  window.addEventListener("mouseup", (e) => { if (drag) onUp(drag.name, e); });  // also when let go outside
  window.addEventListener("resize", () => { sizeCanvases(); render(); });
}

// Only the fields of the chosen method: a [data-setting] field shows if the catalogue lists that setting for it
// (session.info's "settings"), the boxes' fields if it is fitted from boxes.
function showMethodFields() {
  const method = $("method").value;
  document.querySelectorAll("[data-setting]").forEach((el) => { el.hidden = !S.info.settings[method].includes(el.dataset.setting); });
  $("boxes-fields").hidden = !fromBoxes(method);
}

function sizeCanvases() {
  for (const name of ["frame", "map"]) {
    const c = $(name), r = c.getBoundingClientRect();
    c.width = Math.round(r.width); c.height = Math.round(r.height);
    fitView(name);
  }
}

async function start() {
  S.info = await (await fetch("/api/session")).json();
  S.camera = S.info.camera_origin;
  $("title").textContent = S.info.title;
  $("out-dir").textContent = "folder: " + S.info.out_dir;
  $("camera-x").value = S.camera[0]; $("camera-y").value = S.camera[1];
  $("method").innerHTML = S.info.methods.map((m) => `<option>${m}</option>`).join("");
  $("method").value = S.info.default_method;
  $("threshold").value = S.info.threshold;
  $("lens-terms").replaceChildren(...S.info.lens_terms.map((t) => new Option(t)));
  $("lens-terms").value = S.info.lens_defaults.terms;
  $("lens-hfov").value = S.info.lens_defaults.hfov_deg;
  showMethodFields();
  if (S.info.dataset) { $("use-hand-placed").hidden = false; $("use-calibration").hidden = false; }
  for (const s of S.info.box_settings) {  // one field per PedestrianCorrector setting, from its declaration
    const input = s.choices ? Object.assign(document.createElement("select"), { id: s.id, title: s.help })
      : Object.assign(document.createElement("input"), s.low === null
      ? { id: s.id, type: "checkbox", checked: s.default === true, title: s.help }
      : { id: s.id, className: "num", type: "number", step: "0.01", min: s.low, max: s.high, title: s.help,
          placeholder: s.default === null ? "" : String(s.default) });
    if (s.choices) {
      input.replaceChildren(...s.choices.map((c) => new Option(c)));
      input.value = s.default === true ? "yes" : s.default === false ? "no" : s.default;
    }
    input.addEventListener("change", () => { invalidateFit(); invalidateWatch(); render(); });
    const label = document.createElement("label");
    label.append(`${s.id.replace(/-/g, " ")} `, input, ` ${s.unit}${s.none ? ` (empty: ${s.none})` : ""} `);
    $("box-settings").append(label);
  }
  if (S.info.boxes) {
    $("detector").replaceChildren(...S.info.boxes.detectors.map((d) => new Option(d)));  // names from the file: text, never HTML
    if (S.info.boxes.detectors.includes("segmentation")) $("detector").value = "segmentation";
    $("detector").hidden = !S.info.boxes.detectors.length;
    if (S.info.boxes.camera_height_m !== null) $("camera-height").value = S.info.boxes.camera_height_m;
    $("boxes-file").textContent = S.info.boxes.file;
    $("watch-fields").hidden = false;
  }
  await Promise.all(["frame", "map"].map((name) => new Promise((resolve, reject) => {
    images[name].onload = resolve; images[name].onerror = () => reject(new Error(`cannot load /${name}.png`));
    images[name].src = `/${name}.png`;
  })));
  sizeCanvases();
  bind();
  render();
  document.body.dataset.ready = "1";
}

// The page's hook for its browser tests and scripts/screenshots.py: its state, the view transforms, a click at an
// image (or map) pixel as the mouse gives it, and what the last render drew (drawn).
window.homocalUI = { S, views, toScreen, clickAt, drawn, idle: () => inFlight === 0 && !dragAgain };
start().catch((e) => say(e.message, "error", "start"));
