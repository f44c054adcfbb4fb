// The clip of a shaded view (world units).
"use strict";
// Sent with every shaded view (X-ray frames are splatted whole: none): a crop box of the content's world box (the
// hello's), its sliders at their ends no box, and a plane: normal to an axis, or facing the camera (its normal the
// view's direction, recomputed as the view turns), placed by its slider across the box (the view's: across its
// bounding sphere). The server makes the clwave.Clip; one that keeps nothing is its line on the status line.
const AXES = ["x", "y", "z"], STEPS = 1000;
const clipOf = () => {
  const [lo, hi] = hello.model.box, at = (i, v) => lo[i] + (hi[i] - lo[i]) * v / STEPS;
  const ends = AXES.map((a, i) => [at(i, +$(`clip-${a}0`).value), at(i, +$(`clip-${a}1`).value)]);
  const cropped = AXES.some((a) => +$(`clip-${a}0`).value > 0 || +$(`clip-${a}1`).value < STEPS);
  const box = cropped ? [...ends.map((e) => e[0]), ...ends.map((e) => e[1])] : null;
  const planes = $("clip-plane").checked ? [plane(lo, hi, +$("clip-at").value / STEPS)] : [];
  return box || planes.length ? { box, planes } : null;
};
const plane = (lo, hi, t) => {  // [point, normal]: the normal towards what is kept
  const axis = $("clip-axis").value, centre = lo.map((l, i) => (l + hi[i]) / 2);
  if (axis !== "view") {
    const i = AXES.indexOf(axis[1]), point = centre.slice(), normal = [0, 0, 0];
    point[i] = lo[i] + (hi[i] - lo[i]) * t; normal[i] = axis[0] === "+" ? 1 : -1;
    return [...point, ...normal];
  }
  // away from the camera: view_frame's n (clwave/model/geometry.py) points towards it
  const a = state.azimuth * Math.PI / 180, b = state.elevation * Math.PI / 180;
  const away = [-Math.cos(a) * Math.cos(b), -Math.sin(a) * Math.cos(b), -Math.sin(b)];
  const r = Math.hypot(...lo.map((l, i) => hi[i] - l)) / 2;
  return [...centre.map((c, i) => c + away[i] * r * (2 * t - 1)), ...away];
};
const showClip = () => {
  const [lo, hi] = hello.model.box, f = (x) => String(+x.toPrecision(3));
  AXES.forEach((a, i) => {
    const at = (v) => lo[i] + (hi[i] - lo[i]) * v / STEPS;
    $(`clip-${a}-out`).textContent = `${f(at(+$(`clip-${a}0`).value))} … ${f(at(+$(`clip-${a}1`).value))}`;
  });
  $("clip-at").disabled = !$("clip-plane").checked;
  $("clip-at-out").textContent = `${(100 * $("clip-at").value / STEPS).toFixed(0)} %`;
};
AXES.forEach((a) => [0, 1].forEach((end) => {
  const slider = $(`clip-${a}${end}`), other = $(`clip-${a}${1 - end}`);
  slider.addEventListener("input", () => {  // the low end stays below the high one
    if (+$(`clip-${a}0`).value >= +$(`clip-${a}1`).value) slider.value = +other.value + (end ? 1 : -1);
    showClip(); state.moving = true; request();
  });
  slider.addEventListener("change", () => { state.moving = false; request(); });
}));
$("clip-at").addEventListener("input", () => { showClip(); state.moving = true; request(); });
for (const id of ["clip-at", "clip-plane", "clip-axis"]) {
  $(id).addEventListener("change", () => { showClip(); state.moving = false; request(); });
}
$("clip-reset").addEventListener("click", () => {
  AXES.forEach((a) => { $(`clip-${a}0`).value = 0; $(`clip-${a}1`).value = STEPS; });
  $("clip-plane").checked = false; showClip(); state.moving = false; request();
});
