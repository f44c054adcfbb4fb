// The page's state over a reload.
"use strict";
// Each still view sent is kept in the address's hash (#view=…: a reload, or the address as a link, shows it again;
// the token stays in the query, the hash never reaches the server) and, with the transfer function's edit history
// and the editor's axes, in this tab's sessionStorage under that hash. Both carry the hello's model id and are
// applied on load to a model of that id only (another file served: the status line says the view was left out);
// each figure is checked against its control's span (a link edited by hand), and one the server refuses all the
// same is forgotten with the page's socket (disconnected), so a reload starts from the server's view.
const KEPT = "clwave-view", CLIP_INPUTS = [...AXES.flatMap((a) => [`clip-${a}0`, `clip-${a}1`]), "clip-plane",
                                            "clip-axis", "clip-at"];
const finite = (x) => typeof x === "number" && Number.isFinite(x);
const within = (lo, hi) => (x) => finite(x) && x >= lo && x <= hi;
const flag = (x) => typeof x === "boolean";
const LOOK = { azimuth: within(-1e6, 1e6), elevation: within(-90, 90), zoom: within(0.1, 50),
               detail: within(1e-3, 1), background: within(0, 1), shading: flag, scale_bar: flag, edge_labels: flag,
               fov: (x) => x === null || within(5, 120)(x), mode: (x) => hello.modes.includes(x),
               colour_map: (x) => typeof x === "string" && Object.hasOwn(hello.colour_maps, x),
               window: (x) => x === null || (Array.isArray(x) && x.length === 2 && x.every(finite) && x[0] < x[1]) };
const keep = () => {
  if (!hello) return;  // nothing shown yet
  const look = {}, clip = {};
  for (const key in LOOK) look[key] = state[key];
  for (const id of CLIP_INPUTS) clip[id] = $(id).type === "checkbox" ? $(id).checked : +$(id).value;
  const hash = "#view=" + encodeURIComponent(JSON.stringify({ model: hello.model_id, look, tf, clip }));
  if (hash !== location.hash) history.replaceState(null, "", hash);
  try {
    sessionStorage.setItem(KEPT, JSON.stringify({ hash, done, undone, editor: { axis: editor.axis, top: editor.top,
                                                                               window: editor.window, anchor: editor.anchor } }));
  } catch (e) { /* storage full or refused: the hash keeps the view, the history is the tab's */ }
};
const forget = () => {
  history.replaceState(null, "", location.pathname + location.search);
  try { sessionStorage.removeItem(KEPT); } catch (e) { /* nothing kept */ }
};
const tfKept = (t) => {  // the kept transfer function (base and sliders), checked as the server checks what it makes
  const s = t && t.sliders, b = t && t.base;
  if (!s || !b || !within(-MAX_SHIFT, MAX_SHIFT)(s["tf-window"]) || !within(0, 100)(s["tf-width"]) ||
      !within(0, 100)(s["tf-opacity"])) return false;
  if (!b.points) return b.preset === null || hello.presets.includes(b.preset);
  const p = b.points, value = within(-1e30, 1e30), unit = within(0, 1);
  return Array.isArray(p) && p.length >= 2 && p.length <= MAX_POINTS && p.every((q, i) => Array.isArray(q) &&
    q.length === 5 && value(q[0]) && q.slice(1, 4).every(unit) && within(0, MAX_OPACITY)(q[4]) &&
    (!i || q[0] > p[i - 1][0])) && Array.isArray(b.anchor) && b.anchor.length === 2 && b.anchor.every(finite) &&
    b.anchor[0] < b.anchor[1];
};
const clipKept = (c) => {  // the clip's inputs: the sliders' steps, each low end below its high one, an axis offered
  const step = within(0, STEPS);
  return c && AXES.every((a) => step(c[`clip-${a}0`]) && step(c[`clip-${a}1`]) && c[`clip-${a}0`] < c[`clip-${a}1`]) &&
    step(c["clip-at"]) && flag(c["clip-plane"]) &&
    [...$("clip-axis").options].some((o) => o.value === c["clip-axis"]);
};
const restore = (editable) => {  // in setup: the kept view, where it is this model's, before the first view is sent
  let kept = null;
  try { kept = location.hash.startsWith("#view=") && JSON.parse(decodeURIComponent(location.hash.slice(6))); }
  catch (e) { kept = null; }
  if (!kept || typeof kept !== "object") return;
  if (kept.model !== hello.model_id) {
    stats.restored = "another model";
    status.textContent = "the view in this page's address is of another model: left out";
    return;
  }
  const look = kept.look || {};
  for (const key in LOOK) if (key in look && LOOK[key](look[key])) state[key] = look[key];
  if (state.fov !== null) state.scale_bar = false;
  document.querySelector(`input[name="mode"][value="${state.mode}"]`).checked = true;
  $("detail").value = Math.round(1000 * (Math.log10(state.detail) + 3) / 3);
  $("colour-map").value = state.colour_map;
  $("background").value = Math.round(100 * state.background);
  $("background-out").textContent = state.background.toFixed(2);
  $("shading").checked = state.shading;
  $("perspective").checked = $("scale-bar").disabled = state.fov !== null;
  $("fov").disabled = state.fov === null;
  if (state.fov !== null) $("fov").value = state.fov;
  $("scale-bar").checked = state.scale_bar;
  $("edge-labels").checked = state.edge_labels;
  if (clipKept(kept.clip)) {
    for (const id of CLIP_INPUTS) $(id)[$(id).type === "checkbox" ? "checked" : "value"] = kept.clip[id];
  }
  let mine = null;
  try { mine = JSON.parse(sessionStorage.getItem(KEPT)); } catch (e) { mine = null; }
  if (editable && tfKept(kept.tf)) {
    tf = kept.tf;
    if (mine && mine.hash === location.hash) {  // this tab's own, written with the view
      done.push(...mine.done); undone.push(...mine.undone);
      Object.assign(editor, mine.editor, { fresh: false });
    }
    sendTf(false);
  }
  syncMode(); showHistory(); showDetail(); showWindow(); showFov(); showClip(); drawColourBar();
  stats.restored = "applied";
};
