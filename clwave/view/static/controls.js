// The view's controls: orbit, zoom and reset on the image; the standard views; the mode, the X-ray's detail, window
// and colour map; the lighting and background; the perspective and the scale bar.
"use strict";
// ---------------------------------------------------------------- orbit, zoom, reset
let drag = null, idleTimer = null;
canvas.addEventListener("pointerdown", (ev) => {
  if (closed) return;
  drag = { x: ev.clientX, y: ev.clientY };
  canvas.setPointerCapture(ev.pointerId);
  canvas.classList.add("dragging");
});
canvas.addEventListener("pointermove", (ev) => {
  if (!drag) return;
  const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
  if (!dx && !dy) return;
  drag = { x: ev.clientX, y: ev.clientY };
  // dragging right turns the volume right: the camera (azimuth, paper eq. 31) goes the other way
  state.azimuth = ((state.azimuth - 0.4 * dx) % 360 + 360) % 360;
  state.elevation = Math.max(-90, Math.min(90, state.elevation + 0.4 * dy));
  state.moving = true;
  request();
});
const release = () => {
  if (!drag) return;
  drag = null;
  stats.released = performance.now();
  canvas.classList.remove("dragging");
  state.moving = false;
  request();
};
canvas.addEventListener("pointerup", release);
canvas.addEventListener("pointercancel", release);
canvas.addEventListener("wheel", (ev) => {
  ev.preventDefault();
  if (closed) return;
  state.zoom = Math.max(0.1, Math.min(50, state.zoom * Math.exp(-0.0015 * ev.deltaY)));
  state.moving = true;
  request();
  clearTimeout(idleTimer);
  idleTimer = setTimeout(() => { state.moving = false; request(); }, 200);
}, { passive: false });
canvas.addEventListener("dblclick", () => { if (!closed) { Object.assign(state, HOME, { moving: false }); request(); } });

// ---------------------------------------------------------------- standard views
// The hello's views (the server's table, geometry.VIEWS, each with the label of its side, orientation.py): a button
// each, and its name's initial as a key, set the camera's angles, keeping the zoom and the perspective.
const lookFrom = (name) => {
  if (closed || !hello) return;
  const { azimuth, elevation } = hello.views[name];
  Object.assign(state, { azimuth, elevation, moving: false });
  request();
};
const setupViews = () => {
  $("views").replaceChildren("from ", ...Object.entries(hello.views).map(([name, v]) => {
    const button = document.createElement("button");
    button.type = "button"; button.id = `view-${name}`; button.textContent = v.side;
    button.title = `the ${name} view: from the ${v.side} side (azimuth ${v.azimuth}°, elevation ${v.elevation}°; ` +
      `the key ${name[0]})`;
    button.addEventListener("click", () => lookFrom(name));
    return button;
  }));
};
document.addEventListener("keydown", (ev) => {
  if (ev.ctrlKey || ev.metaKey || ev.altKey || !hello || ev.target.closest("input, select, textarea")) return;
  const name = Object.keys(hello.views).find((n) => n[0] === ev.key.toLowerCase());
  if (name) { lookFrom(name); ev.preventDefault(); }
});
// the edges' labels of the frame drawn (its figures' orientation, made with its camera on the server)
const showEdges = (f) => {
  for (const edge of ["left", "right", "top", "bottom"]) {
    $(`edge-${edge}`).textContent = f.orientation[edge];
    $(`edge-${edge}`).hidden = !state.edge_labels;
  }
};
$("edge-labels").addEventListener("change", (ev) => {
  state.edge_labels = ev.target.checked;
  for (const edge of ["left", "right", "top", "bottom"]) $(`edge-${edge}`).hidden = !state.edge_labels;
  keep();
});

// ---------------------------------------------------------------- controls
const syncMode = () => {
  $("xray-controls").disabled = state.mode !== "xray";
  $("shaded-controls").disabled = state.mode !== "shaded";
  $("colour-scale").hidden = state.mode !== "xray" || !hello.capabilities.xray.colour_map;
};
document.querySelectorAll('input[name="mode"]').forEach((r) => r.addEventListener("change", () => {
  state.mode = r.value; syncMode(); request();
}));
// detail: a log scale from 0.1 % to all of the kept coefficients
const detailOf = (v) => Math.pow(10, -3 + 3 * v / 1000);
const showDetail = () => {
  const d = detailOf(+$("detail").value);
  $("detail-out").textContent = `${(100 * d).toFixed(d >= 0.1 ? 0 : d >= 0.01 ? 1 : 2)} %`;
  return d;
};
$("detail").addEventListener("input", () => { state.detail = showDetail(); request(); });
// window sliders span 0 .. 2 x the auto window's top
const span = () => 2 * Math.max(hello.window[1], 1e-30);
// a colour bar's label: three digits, an exponent without its "+" and a mantissa without trailing zeros
const short = (x) => x.toPrecision(3).replace(/(\.\d*?)0+(?=e|$)/, "$1").replace(/\.(?=e|$)/, "").replace("e+", "e");
const showWindow = () => {  // the sliders, their figures and the colour bar's labels
  const [lo, hi] = state.window || hello.window;
  $("lo").value = Math.round(1000 * lo / span()); $("hi").value = Math.round(1000 * hi / span());
  $("lo-out").textContent = lo.toPrecision(3);
  $("hi-out").textContent = hi.toPrecision(3);
  $("bar-lo").textContent = short(lo); $("bar-hi").textContent = short(hi);
  $("bar-mid").textContent = short((lo + hi) / 2);
  // three labels of up to 7 characters need about 150 px: under the bar of a smaller image, the low and high alone
  // (which wrap, never run together, under a bar narrower than two)
  $("bar-mid").hidden = hello.size[1] < 200;
};
const drawColourBar = () => {  // the colour map's 256 rows (the hello's, base64 of RGB bytes) from low to high
  const rows = atob(hello.colour_maps[state.colour_map]), c = $("colour-bar").getContext("2d");
  const image = c.createImageData(256, 1);
  for (let i = 0; i < 256; i++) {
    for (let j = 0; j < 3; j++) image.data[4 * i + j] = rows.charCodeAt(3 * i + j);
    image.data[4 * i + 3] = 255;
  }
  c.putImageData(image, 0, 0);
};
const moveWindow = () => {
  const lo = span() * $("lo").value / 1000, hi = span() * $("hi").value / 1000;
  if (hi > lo) { state.window = [lo, hi]; showWindow(); request(); }
};
$("lo").addEventListener("input", moveWindow);
$("hi").addEventListener("input", moveWindow);
$("auto-window").addEventListener("click", () => { state.window = null; showWindow(); request(); });
$("colour-map").addEventListener("change", (ev) => { state.colour_map = ev.target.value; drawColourBar(); request(); });
$("shading").addEventListener("change", (ev) => { state.shading = ev.target.checked; request(); });
$("background").addEventListener("input", (ev) => {
  state.background = ev.target.value / 100; $("background-out").textContent = state.background.toFixed(2); request();
});

// ---------------------------------------------------------------- perspective (the server places the eye, frames.py)
const showFov = () => { $("fov-out").textContent = `${$("fov").value}°`; };
$("perspective").addEventListener("change", (ev) => {
  $("fov").disabled = !ev.target.checked; $("scale-bar").disabled = ev.target.checked;
  state.fov = ev.target.checked ? +$("fov").value : null; state.moving = false; request();
  state.scale_bar = $("scale-bar").checked && !ev.target.checked;
});
$("scale-bar").addEventListener("change", (ev) => { state.scale_bar = ev.target.checked; drawScaleBar(); keep(); });
$("fov").addEventListener("input", () => { showFov(); state.fov = +$("fov").value; state.moving = true; request(); });
$("fov").addEventListener("change", () => { state.moving = false; request(); });
