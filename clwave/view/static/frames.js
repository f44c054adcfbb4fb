// The frames: decoded and drawn (the latest view's only), their figures, the model's line, the scale bar over them
// and the PNG saved.
"use strict";
let current = null, received = 0, drawn = 0;
const onFrame = (buffer) => {
  stats.received += 1;
  const n = new DataView(buffer).getUint32(0);
  const fig = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n)));
  if (fig.seq !== sentSeq) { stats.dropped += 1; return; }  // a frame of a view the user has left
  const blob = new Blob([new Uint8Array(buffer, 4 + n)], { type: fig.mime }), k = ++received;
  next(fig);  // a drag's next view goes now: the server renders it while this frame decodes and is drawn
  createImageBitmap(blob).then((bitmap) => {
    // decoded off the main thread: drawn unless a frame that arrived later has been drawn meanwhile (this one
    // was of the latest view when it arrived)
    if (k < drawn) { stats.dropped += 1; bitmap.close(); return; }
    drawn = k;
    ctx.drawImage(bitmap, 0, 0, canvas.width, canvas.height);  // a smaller frame (while dragging) scaled up
    bitmap.close();
    const now = performance.now();
    if (stats.firstImage === null) stats.firstImage = now;  // since the page's navigation started
    stats.shown += 1;
    stats.frames.push({ seq: fig.seq, final: fig.final, moving: state.moving, at: now, seconds: fig.seconds,
                        width: fig.width });
    if (stats.frames.length > 500) stats.frames.shift();
    current = { fig, blob };
    showFigures(fig);
    showEdges(fig);
    drawScaleBar();
  });
};

const showModel = () => {
  const m = hello.model;
  $("model").textContent = `${m.shape.slice().reverse().join(" × ")} voxels, ${m.channels} channel(s), ` +
    `${m.wavelets.join(", ")}, ${m.coefficients.toLocaleString()} coefficients ` +
    (m.reading ? "(the file's most important; reading the rest…)" : m.failure ? "(the file's most important " +
     `only: the rest could not be read, ${m.failure})` : "kept") +
    (m.transfer_function ? `, classified with ${m.transfer_function}` : "") + values(m, editor.histogram) +
    modelError(m);
};
const values = (m, h) => {  // the input's range and the model's field against it (once)
  if (m.channels !== 1) return "";
  const r = (v) => v.map((x) => String(+x.toPrecision(4))).join(" … ");
  return (m.value_range ? `. Input values ${r(m.value_range)}` : ". Input values not known (a file written " +
          "before clwave kept them: classified as the model's field)") +
    (h && m.value_range ? `; the model's field ${r(h.field)}, classified clamped to the input's` : "");
};
const modelError = (m) => {  // a file's recorded error against its input (viewer.md §4), not the frames' error
  const e = m.error ? m.error.rms : null;
  const part = m.error && (!m.error.whole || m.reading || m.failure);  // the view holds fewer than the file's
  return ". The model's error against the input: " + (e !== null ? `RMS ${e.toPrecision(3)} of the largest ` +
    `value (PSNR ${(-20 * Math.log10(Math.max(e, 1e-30))).toFixed(1)} dB)` + (part ? ", the whole file's" : "") :
    m.error ? "not recorded in the file (clwave compress records it where it reads the input whole)" :
    "not known (a model made here, not read from a .clw)") +
    "; the frames' error is against the model's final image";
};

// ---------------------------------------------------------------- the scale bar over an orthographic view
// Its length and label are the server's (the frame's scale_bar: --scale-bar's default for this extent, frames.py);
// drawn here at the bottom right, white outlined in black as io/images.draw_scale_bar burns it into a saved image.
const drawScaleBar = () => {
  octx.clearRect(0, 0, overlay.width, overlay.height);
  const f = current && current.fig;
  if (!state.scale_bar || !f || !f.scale_bar) return;
  const [length, label] = f.scale_bar, size = Math.max(12, Math.round(Math.min(overlay.width, overlay.height) / 24));
  const bar = Math.round(length / f.extent * overlay.width), thick = Math.max(2, Math.round(size / 4));
  const rim = Math.max(1, Math.round(size / 9)), margin = Math.max(4, Math.round(size / 2));
  const x1 = overlay.width - margin - rim, y1 = overlay.height - margin - rim;
  octx.fillStyle = "#000"; octx.fillRect(x1 - bar - rim, y1 - thick - rim, bar + 2 * rim, thick + 2 * rim);
  octx.fillStyle = "#fff"; octx.fillRect(x1 - bar, y1 - thick, bar, thick);
  octx.font = `${size}px sans-serif`; octx.textAlign = "center"; octx.textBaseline = "bottom";
  const x = Math.min(x1 - bar / 2, overlay.width - margin - octx.measureText(label).width / 2);
  octx.lineWidth = 2 * rim; octx.strokeStyle = "#000"; octx.lineJoin = "round";
  octx.strokeText(label, x, y1 - thick - rim - 2); octx.fillText(label, x, y1 - thick - rim - 2);
};

// ---------------------------------------------------------------- figures and saving
const fmt = (x, d = 3) => (typeof x === "number" ? x.toPrecision(d) : String(x));
// a frame short of final: what it waits for (an X-ray's prefix, a shaded coarse frame's "reading" or "set-up")
const waitingWords = (f) => f.prefix ? "refined from the file's most important part; the rest is being read…"
  : f.waiting === "reading" ? `coarse (detail ${f.detail}) while the rest of the file is read…`
  : f.waiting === "set-up" ? `coarse (detail ${f.detail}) while the ray tracer is set up…` : "refining…";
const showFigures = (f) => {
  const rows = [["view", `az ${f.azimuth.toFixed(1)}°, el ${f.elevation.toFixed(1)}°`],
                ["image", `${f.width} × ${f.height}${f.final ? ", final" : ""}`]];
  if (f.mode === "xray") {
    rows.push(["coefficients", `${f.coefficients.toLocaleString()} (${(100 * f.fraction).toPrecision(3)} %)`]);
    rows.push(["error estimate", `${fmt(f.error)} (${f.error_kind})`]);
  } else {
    rows.push(["tolerance", `${fmt(f.tolerance)}, detail ${f.detail}` +
               (f.reduction > 1 ? `, 1/${f.reduction} size` : "")]);
    if (f.error !== null) rows.push(["frame's error", `${fmt(f.error)} (${f.error_kind})`]);
    if (f.tf_window) $("tf-range").textContent = showRange(f.tf_window);  // the window this frame was classified by
    // the function it was classified by, where that is the function now (not one left since it was sent)
    if (f.tf_points && !tf.base.points && f.seq === sentSeq && !pending) framePoints(f.tf_points, f.tf_window);
  }
  rows.push(["frame", `${(1000 * f.seconds).toFixed(0)} ms render, ${(1000 * f.elapsed).toFixed(0)} ms since view` +
             (f.build_seconds ? ` (${(1000 * f.build_seconds).toFixed(0)} ms waiting for the ray tracer's build)` : "")]);
  const table = $("figures");
  table.replaceChildren(...rows.map(([k, v]) => {
    const tr = document.createElement("tr");
    for (const text of [k, v]) { const td = document.createElement("td"); td.textContent = text; tr.append(td); }
    return tr;
  }));
  $("save").disabled = !(f.final && f.mime === "image/png");
  if (closed) return;  // a frame decoded after the socket closed: the status line still says so
  status.classList.remove("error");
  status.textContent = f.note ? f.note : f.final ? "refined" : state.moving ? "moving" : waitingWords(f);
};
$("save").addEventListener("click", () => {
  if (!current || !current.fig.final) return;
  const a = document.createElement("a"), f = current.fig;
  a.href = URL.createObjectURL(current.blob);
  a.download = `clwave_${f.mode}_az${f.azimuth.toFixed(0)}_el${f.elevation.toFixed(0)}.png`;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
});
