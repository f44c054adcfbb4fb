// clwave viewer page (docs/viewer.md §4): what its scripts share; index.html loads them in order, viewer.js last.
"use strict";
const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token") || "";
const canvas = $("image"), ctx = canvas.getContext("2d"), status = $("status");
const overlay = $("scale-bar-overlay"), octx = overlay.getContext("2d");  // the scale bar over the image
const HOME = { azimuth: 30, elevation: 20, zoom: 1 };  // the hello's home replaces the angles
const state = { ...HOME, mode: "xray", detail: 1, window: null, moving: false, background: 0, shading: true,
                tf: null, colour_map: "grey", fov: null, scale_bar: false, edge_labels: true };
// what the tests and tools/bench.py read: frames received, shown, dropped as superseded; times in ms
const stats = { received: 0, shown: 0, dropped: 0, firstImage: null, released: null, tfInput: null, frames: [],
                exported: null, saved: null, restored: null };

const showRange = (w) => {  // a transfer function's window in data units ("auto": the volume's percentiles)
  return w === "auto" ? "auto" : w.map((v) => String(+v.toPrecision(4))).join(" … ");
};
