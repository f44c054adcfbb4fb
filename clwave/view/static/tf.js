// The transfer function of a shaded view: its sliders and presets, their undo and redo, the editor of its points.
"use strict";
// A scalar model's, classified while rendering: a base, a preset (null: the starting function,
// whose window the server holds) or the editor's points (data units, with the window `anchor` they are scaled about),
// seen through the sliders: the window centre and width move and widen the base's window, so its points move and
// scale together; the opacity scale multiplies their opacities. A preset base goes to the server as such (it applies
// the sliders alike, ShadedSource.transfer_function), points go through them. Editing the points shown makes them the
// base (through the sliders backwards: the sliders stay and go on acting); a preset replaces the base, sliders centred.
// A slider being moved asks for the cheap frames of a drag, its release for the refined view. The window centre's
// slider is in data units over the input's range (the histogram's), kept in it; held as the shift of the base's
// window in its widths (as the server takes it), known once the base's window is (a preset's: its first frame).
const TF_SLIDERS = { "tf-window": (v) => v, "tf-width": (v) => 10 ** ((v - 50) / 50),
                     "tf-opacity": (v) => 10 ** ((v - 50) / 25) };
const CENTRED = { "tf-window": 0, "tf-width": 50, "tf-opacity": 50 }, MAX_OPACITY = 1000;  // protocol.POINT_RANGES
const MAX_SHIFT = 1e6;  // protocol.TF_RANGES' centre
let tf = { base: { preset: null }, sliders: { ...CENTRED } };
const slider = (id) => TF_SLIDERS[id](tf.sliders[id]);
const through = (points, anchor, back) => {  // points seen through the sliders (back: the points seen, through them back)
  const mid = (anchor[0] + anchor[1]) / 2, shift = slider("tf-window") * (anchor[1] - anchor[0]);
  const k = slider("tf-width"), o = slider("tf-opacity");
  return points.map(([v, r, g, b, a]) => (back ? [mid + (v - mid - shift) / k, r, g, b, a / o] :
                                                 [mid + shift + (v - mid) * k, r, g, b, Math.min(MAX_OPACITY, a * o)]));
};
const sendTf = (moving) => {  // the function as the server gets it
  const base = tf.base;
  if (base.points) {
    editor.points = through(base.points, base.anchor);
    fitEditor(editor.fresh);
    // colours and opacities rounded (a message stays far under 4 KiB); values as they are, whose order rounding to
    // fewer digits could break where they lie close together far from zero (a refused message closes the socket)
    state.tf = { points: editor.points.map((p) => [p[0], ...p.slice(1, 4).map((x) => +x.toFixed(4)),
                                                   +p[4].toPrecision(6)]) };
  } else {
    state.tf = { preset: base.preset, centre: slider("tf-window"), width: slider("tf-width"),
                 opacity: slider("tf-opacity") };
  }
  for (const id in TF_SLIDERS) { $(id).value = tf.sliders[id]; $(id + "-out").textContent = slider(id).toPrecision(2); }
  showCentre();
  $("tf-preset").value = base.points ? EDITED : base.preset || "";
  state.moving = moving;
  drawEditor();
  request();
};
const anchorNow = () => tf.base.anchor || editor.anchor;  // the base's window in data units, or null (not yet known)
const showCentre = () => {  // the centre slider in data units: its span the input's range, its value the window's centre
  const a = anchorNow(), el = $("tf-window"), mid = a && (a[0] + a[1]) / 2 + slider("tf-window") * (a[1] - a[0]);
  const span = editor.histogram ? editor.histogram.range : a ? [mid - 2 * (a[1] - a[0]), mid + 2 * (a[1] - a[0])] : [0, 1];
  el.min = span[0]; el.max = span[1] > span[0] ? span[1] : span[0] + 1; el.step = "any";
  el.disabled = !a;
  if (a) el.value = mid;
  $("tf-window-out").textContent = a ? String(+mid.toPrecision(4)) : "";
};
const centreTo = (value) => {  // the window's centre moved to ``value`` (data units): the shift in the base's widths
  const a = anchorNow();
  if (!a || !(a[1] > a[0])) return false;
  const shift = (value - (a[0] + a[1]) / 2) / (a[1] - a[0]);
  tf.sliders["tf-window"] = Math.min(MAX_SHIFT, Math.max(-MAX_SHIFT, shift));
  return true;
};
for (const id in TF_SLIDERS) {
  $(id).addEventListener("input", (ev) => {
    begin();
    if (id !== "tf-window") tf.sliders[id] = +ev.target.value;
    else if (!centreTo(+ev.target.value)) return;
    sendTf(true);
    if (stats.tfInput === null) stats.tfInput = performance.now();
  });
  $(id).addEventListener("change", () => { commit(); state.moving = false; request(); });
}
$("tf-preset").addEventListener("change", (ev) => {
  if (ev.target.value === EDITED) return;  // chosen by editing only
  begin(); tf = { base: { preset: ev.target.value || null }, sliders: { ...CENTRED } };
  Object.assign(editor, { fresh: true, anchor: null });
  sendTf(false); commit();
});

// ---------------------------------------------------------------- undo, redo
// Transfer-function edits: a gesture (a slider's or a point's drag, a colour picked, a preset) is one step, the
// last HISTORY kept, with the editor as it was (its axes, and a preset's points and window: a step back shows the
// function as it was seen); Ctrl+Z undoes, Ctrl+Shift+Z or Ctrl+Y redoes (as the buttons), while the editor acts.
const HISTORY = 100, done = [], undone = [];
let before = null;  // the function as a gesture under way found it
const seen = () => ({ tf: JSON.stringify(tf), axis: editor.axis, top: editor.top, window: editor.window,
                      anchor: editor.anchor,
                      points: editor.points && editor.points.map((p) => p.slice()) });  // (edits change them in place)
const begin = () => { if (before === null) before = seen(); };
const commit = () => {
  if (before !== null && before.tf !== JSON.stringify(tf)) {
    done.push(before); undone.length = 0;
    if (done.length > HISTORY) done.shift();
  }
  before = null;
  showHistory();
};
const showHistory = () => { $("tf-undo").disabled = !done.length; $("tf-redo").disabled = !undone.length; };
const step = (from, to) => {
  if (!from.length || before !== null || tfCanvas.closest("fieldset:disabled")) return;
  to.push(seen());
  const back = from.pop();
  tf = JSON.parse(back.tf);
  Object.assign(editor, { axis: back.axis, top: back.top, window: back.window, anchor: back.anchor,
                          points: back.points });
  select(-1); sendTf(false); showHistory();
};
$("tf-undo").addEventListener("click", () => step(done, undone));
$("tf-redo").addEventListener("click", () => step(undone, done));
document.addEventListener("keydown", (ev) => {
  if (!(ev.ctrlKey || ev.metaKey) || ev.altKey) return;
  const key = ev.key.toLowerCase();
  if (key === "z" && !ev.shiftKey) step(done, undone);
  else if (key === "y" || key === "z") step(undone, done);
  else return;
  ev.preventDefault();
});

// ---------------------------------------------------------------- transfer-function points
// The canvas shows the opacity over the scalar's values (their histogram behind it, log counts): the points of the
// function (in data units): a preset's as the last shaded frame was classified by them (and its window), the
// base's through the sliders once the user edits them (click: add, drag: move, double-click or Delete: remove, the
// colour input: the selected point's colour). Values stay strictly increasing, GAP of the axis apart. The axes hold
// the values and the points: made anew with a preset (`fresh`), else only widened (an undo restores them).
const EDITED = "edited", MAX_POINTS = 32, GAP = 1e-3, PAD = 5, HIT = 7;
const tfCanvas = $("tf-editor"), tfCtx = tfCanvas.getContext("2d");
const editor = { points: null, window: null, anchor: null, axis: [0, 1], top: 1, fresh: true, selected: -1,
                 drag: false, changed: false, histogram: null };
const xOf = (v) => PAD + (v - editor.axis[0]) / (editor.axis[1] - editor.axis[0]) * (tfCanvas.width - 2 * PAD);
const yOf = (a) => tfCanvas.height - PAD - a / editor.top * (tfCanvas.height - 2 * PAD);
const valueOf = (x) => editor.axis[0] + Math.min(1, Math.max(0, (x - PAD) / (tfCanvas.width - 2 * PAD))) *
  (editor.axis[1] - editor.axis[0]);
const opacityOf = (y) => editor.top * Math.min(1, Math.max(0, (tfCanvas.height - PAD - y) / (tfCanvas.height - 2 * PAD)));
const css = (p) => `rgb(${p.slice(1, 4).map((c) => Math.round(255 * c)).join(",")})`;

const framePoints = (points, window) => {  // a preset's points and window as a frame was classified by them
  if (editor.drag) return;
  editor.points = points.map((p) => p.slice());
  editor.window = window;
  // a preset's window without the sliders (the frame's are the sliders now: it is the function sent last)
  const w = (window[1] - window[0]) / slider("tf-width"), mid = (window[0] + window[1]) / 2 - slider("tf-window") * w;
  editor.anchor = [mid - w / 2, mid + w / 2];
  showCentre();
  fitEditor(editor.fresh);
  editor.selected = Math.min(editor.selected, points.length - 1);
  drawEditor();
};

const fitEditor = (fresh) => {
  const pts = editor.points, h = editor.histogram ? editor.histogram.range : [pts[0][0], pts[pts.length - 1][0]];
  let lo = Math.min(h[0], pts[0][0]), hi = Math.max(h[1], pts[pts.length - 1][0]);
  if (!fresh) { lo = Math.min(lo, editor.axis[0]); hi = Math.max(hi, editor.axis[1]); }
  editor.axis = hi > lo ? [lo, hi] : [lo - 0.5, lo + 0.5];
  const most = Math.max(...pts.map((p) => p[4]));
  if (fresh || most > editor.top) editor.top = 2 * most || 1;  // room to raise the opacity twofold
  editor.fresh = false;
};

const drawEditor = () => {
  const W = tfCanvas.width, H = tfCanvas.height, c = tfCtx, pts = editor.points;
  c.clearRect(0, 0, W, H);
  if (!pts) {
    c.fillStyle = "#8a939d"; c.font = "11px system-ui, sans-serif";
    c.fillText("the points come with the first shaded frame", PAD, H / 2);
    return;
  }
  $("tf-axis").textContent = showRange(editor.axis);  // what the canvas spans: the input's range and the points
  const hist = editor.histogram;
  if (hist) {
    const [lo, hi] = hist.range, n = hist.counts.length, most = Math.log1p(Math.max(...hist.counts)) || 1;
    c.fillStyle = "#3a3f46";
    hist.counts.forEach((count, i) => {
      const x0 = xOf(lo + (hi - lo) * i / n), x1 = xOf(lo + (hi - lo) * (i + 1) / n);
      const h = Math.log1p(count) / most * (H - 2 * PAD);
      c.fillRect(x0, H - PAD - h, Math.max(1, x1 - x0), h);
    });
  }
  const first = xOf(pts[0][0]), last = xOf(pts[pts.length - 1][0]);
  const colours = c.createLinearGradient(first, 0, Math.max(last, first + 1), 0);
  for (const p of pts) colours.addColorStop(Math.min(1, Math.max(0, (xOf(p[0]) - first) / (last - first || 1))), css(p));
  c.beginPath();  // outside the points the end rows hold
  c.moveTo(0, yOf(pts[0][4]));
  for (const p of pts) c.lineTo(xOf(p[0]), yOf(p[4]));
  c.lineTo(W, yOf(pts[pts.length - 1][4]));
  c.strokeStyle = "#dde1e6"; c.lineWidth = 1.5; c.stroke();
  c.lineTo(W, H - PAD); c.lineTo(0, H - PAD); c.closePath();
  c.globalAlpha = 0.6; c.fillStyle = colours; c.fill(); c.globalAlpha = 1;
  pts.forEach((p, i) => {
    c.beginPath(); c.arc(xOf(p[0]), yOf(p[4]), i === editor.selected ? 5 : 4, 0, 2 * Math.PI);
    c.fillStyle = css(p); c.fill();
    c.strokeStyle = i === editor.selected ? "#ffffff" : "#8a939d"; c.lineWidth = i === editor.selected ? 2 : 1;
    c.stroke();
  });
};

const edited = (moving) => {  // the points shown, edited, are the base through the sliders backwards
  const anchor = anchorNow();  // a preset's: the window its frame was classified by, without the sliders
  tf.base = { points: through(editor.points, anchor, true), anchor };
  if (stats.tfInput === null) stats.tfInput = performance.now();
  sendTf(moving);
};

const select = (i) => {
  editor.selected = i;
  const p = editor.points && editor.points[i];
  $("tf-colour").disabled = !p;
  if (p) $("tf-colour").value = "#" + p.slice(1, 4).map((x) => Math.round(255 * x).toString(16).padStart(2, "0")).join("");
  drawEditor();
};

const canvasAt = (ev) => {  // the pointer in canvas pixels (the canvas is scaled to the panel's width)
  const r = tfCanvas.getBoundingClientRect();
  return [(ev.clientX - r.left) * tfCanvas.width / r.width, (ev.clientY - r.top) * tfCanvas.height / r.height];
};

const hit = (x, y) => {  // the point within HIT pixels, nearest first; -1 for none
  let best = -1, near = HIT * HIT;
  (editor.points || []).forEach((p, i) => {
    const d = (xOf(p[0]) - x) ** 2 + (yOf(p[4]) - y) ** 2;
    if (d <= near) { best = i; near = d; }
  });
  return best;
};

const add = (value, opacity) => {  // a new point, coloured as the function is there; its index, or -1 (too near one)
  const pts = editor.points, gap = GAP * (editor.axis[1] - editor.axis[0]);
  const k = pts.findIndex((p) => p[0] > value), at = k < 0 ? pts.length : k;
  if (pts.length >= MAX_POINTS || (at > 0 && value - pts[at - 1][0] < gap) ||
      (at < pts.length && pts[at][0] - value < gap)) return -1;
  const a = pts[Math.max(0, at - 1)], b = pts[Math.min(pts.length - 1, at)];
  const t = b[0] > a[0] ? (value - a[0]) / (b[0] - a[0]) : 0;
  pts.splice(at, 0, [value, ...[1, 2, 3].map((j) => a[j] + t * (b[j] - a[j])), opacity]);
  return at;
};

const remove = (i) => {
  if (i < 0 || editor.points.length <= 2 || tfCanvas.closest("fieldset:disabled")) return;
  begin();
  editor.points.splice(i, 1);
  select(-1);
  edited(false);
  commit();
};

tfCanvas.addEventListener("pointerdown", (ev) => {
  if (!editor.points || tfCanvas.closest("fieldset:disabled")) return;
  const [x, y] = canvasAt(ev);
  let i = hit(x, y);
  begin();
  editor.changed = i < 0;
  if (i < 0 && (i = add(valueOf(x), opacityOf(y))) < 0) { commit(); return; }
  select(i);
  editor.drag = true;
  tfCanvas.setPointerCapture(ev.pointerId);
  if (editor.changed) edited(true);
});
tfCanvas.addEventListener("pointermove", (ev) => {
  if (!editor.drag) return;
  const [x, y] = canvasAt(ev), pts = editor.points, i = editor.selected;
  const gap = GAP * (editor.axis[1] - editor.axis[0]);
  const lo = i > 0 ? pts[i - 1][0] + gap : editor.axis[0], hi = i < pts.length - 1 ? pts[i + 1][0] - gap : editor.axis[1];
  pts[i][0] = Math.min(hi, Math.max(lo, valueOf(x)));  // between its neighbours: the order never changes
  pts[i][4] = opacityOf(y);
  editor.changed = true;
  edited(true);
});
const letGo = () => {
  if (!editor.drag) return;
  editor.drag = false;
  // a point let go at the top (its top twentieth) doubles the opacity axis: room to raise it further
  if (editor.points[editor.selected][4] > 0.95 * editor.top) editor.top *= 2;
  if (editor.changed) edited(false);
  commit();
};
tfCanvas.addEventListener("pointerup", letGo);
tfCanvas.addEventListener("pointercancel", letGo);
tfCanvas.addEventListener("dblclick", (ev) => remove(hit(...canvasAt(ev))));
tfCanvas.addEventListener("keydown", (ev) => {
  if (ev.key === "Delete" || ev.key === "Backspace") { ev.preventDefault(); remove(editor.selected); }
});
$("tf-colour").addEventListener("input", (ev) => {
  const p = editor.points && editor.points[editor.selected];
  if (!p) return;
  const hex = ev.target.value;
  begin();
  [1, 2, 3].forEach((j) => { p[j] = parseInt(hex.slice(2 * j - 1, 2 * j + 1), 16) / 255; });
  edited(true);
});
$("tf-colour").addEventListener("change", () => { commit(); if (tf.base.points) { state.moving = false; request(); } });
