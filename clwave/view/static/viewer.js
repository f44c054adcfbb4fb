// clwave viewer page (docs/viewer.md §4): sends its whole view on every change, shows the frames of the latest.
"use strict";
(() => {
  const $ = (id) => document.getElementById(id);
  const token = new URLSearchParams(location.search).get("token") || "";
  const canvas = $("image"), ctx = canvas.getContext("2d"), status = $("status");
  const overlay = $("scale-bar-overlay"), octx = overlay.getContext("2d");  // the scale bar over the image
  const HOME = { azimuth: 30, elevation: 20, zoom: 1 };
  const state = { ...HOME, mode: "xray", detail: 1, window: null, moving: false, background: 0, shading: true,
                  tf: null, colour_map: "grey", fov: null, scale_bar: false };
  let sentSeq = 0, hello = null, current = null, pending = false, idleTimer = null, closed = false;
  // what the tests and tools/bench.py read: frames received, shown, dropped as superseded; times in ms
  const stats = { received: 0, shown: 0, dropped: 0, firstImage: null, released: null, tfInput: null, frames: [],
                  exported: null, saved: null, restored: null };
  window.clwave = { state, stats, send: () => request(), current: () => current, view: () => view(),
                    latest: () => (pending || held ? -1 : sentSeq) };  // the view asked for last (-1: one is on its way)

  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws?token=` +
                           encodeURIComponent(token));
  ws.binaryType = "arraybuffer";
  ws.onclose = disconnected;
  ws.onmessage = (ev) => (typeof ev.data === "string" ? onText(JSON.parse(ev.data)) : onFrame(ev.data));

  // While dragging, one view at a time is on its way: the next is sent when its frame arrives (or after a
  // second), so every frame rendered is of the view asked for last and none is dropped; a still view is sent
  // at once (the server abandons what it was refining).
  let awaiting = 0, since = 0, held = false;
  function send() {
    pending = false;
    if (ws.readyState !== WebSocket.OPEN) return;
    if (state.moving && awaiting && performance.now() - since < 1000) { held = true; return; }  // sent with the frame
    held = false;
    sentSeq += 1;
    awaiting = state.moving ? sentSeq : 0;
    since = performance.now();
    ws.send(JSON.stringify(view()));
    if (!state.moving) keep();
  }
  // The socket closed: the server refused a message of this page (policy, size: the page may be reloaded) or this
  // tab (as many are open as it serves), or it stopped or cannot be reached. Nothing answers any more: every control that sends is disabled (greyed), the last
  // image stays (and can still be saved), and the status line says what happened and what to do.
  const REFUSED = [1008, 1009], BUSY = 1013;  // protocol.POLICY, TOO_BIG; server.MAX_TABS open (its reason says)
  function disconnected(ev) {
    closed = true;
    if (REFUSED.includes(ev.code)) forget();  // a kept view the server refused is not shown again by the reload
    for (const id of ["mode", "camera-controls", "xray-controls", "shaded-controls", "export"]) $(id).disabled = true;
    canvas.classList.add("offline");
    const why = `${ev.code}${ev.reason ? ": " + ev.reason : ""}`;
    status.textContent = ev.code === BUSY ? `not connected (${why})` : REFUSED.includes(ev.code) ?
      `disconnected: the server refused a message of this page (${why}); reload the page` :
      `disconnected: the viewer's server has stopped or cannot be reached (${why}); restart clwave view … (or ` +
      "clwave.view) and open the address it prints, whose token is new. This image is the last it sent.";
    status.classList.add("error");
  }
  function view() {  // the message of the view now: a shaded one with its clip (X-ray frames are splatted whole)
    return { type: "view", seq: sentSeq, ...state, clip: hello && state.mode === "shaded" ? clipOf() : null };
  }
  function request() {  // at most one message per 16 ms: the latest state then
    if (!pending) { pending = true; setTimeout(send, 16); }
  }

  function onText(msg) {
    if (msg.type === "hello") { hello = msg; setup(); request(); }
    else if (msg.type === "model") { hello.model = msg.model; showModel(); }  // a file's whole model is in
    else if (msg.type === "histogram") { editor.histogram = msg; drawEditor(); showCentre(); showModel(); }
    else if (msg.type === "status" && msg.seq === sentSeq) status.textContent = msg.message;
    else if (msg.type === "error" && (msg.seq === undefined || msg.seq === sentSeq)) {  // no seq: the server's, not a view's
      status.textContent = msg.message; status.classList.add("error");
      next(msg);
    }
  }

  let received = 0, drawn = 0;
  function onFrame(buffer) {
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
      drawScaleBar();
    });
  }
  function next(fig) {  // a drag's frame has come: its next view goes at once
    if (fig.seq === awaiting) { awaiting = 0; if (held) send(); }
  }

  function setup() {
    const [h, w] = hello.size;
    canvas.width = overlay.width = w; canvas.height = overlay.height = h;
    showModel();
    const shaded = hello.modes.includes("shaded");
    document.querySelector('input[value="shaded"]').disabled = !shaded;
    state.mode = hello.mode;  // shaded where a transfer function was chosen (given, or the model's own)
    document.querySelector(`input[value="${hello.mode}"]`).checked = true;
    $("shaded-note").textContent = shaded ? "" : "shaded needs a scalar or a classified (RGBA) model: " +
      "classify a colour one first (--tf brightfield: stained, on white; --tf photo: by its own alpha)";
    // the first entry is the transfer function the server starts from (given with --tf/--tf-window, the model's
    // own, or grey; preset null), then the presets with their own windows
    const start = hello.tf || { name: "grey", window: "auto" };
    $("tf-preset").replaceChildren(...[null, ...hello.presets, EDITED].map((name) => {
      const option = document.createElement("option");
      option.value = name || "";
      option.textContent = name === EDITED ? "edited points" :
        name || `${start.name || "custom"}, window ${showRange(start.window)} (start)`;
      option.hidden = name === EDITED;
      return option;
    }));
    const editable = shaded && hello.capabilities.shaded.tf;
    $("tf").disabled = !editable;
    $("tf-note").textContent = editable ? "classified while rendering" : "the model was classified before its " +
      "transform (RGBA): lighting and background act";
    $("tf-range").textContent = showRange(start.window);
    if (editable) sendTf(false);
    $("colour-map").replaceChildren(...Object.keys(hello.colour_maps).map((name) => {
      const option = document.createElement("option");
      option.value = option.textContent = name;
      return option;
    }));
    $("colour-map").disabled = !hello.capabilities.xray.colour_map;
    showHistory();
    drawEditor();
    drawColourBar();
    syncMode();
    showDetail(); showWindow(); showFov(); showClip();
    // the saved image's size: the canvas' times 1, 2, 3, 4, 6 or 8, each side at most 4096 (protocol.EXPORT_SIZE)
    $("export-scale").replaceChildren(...[1, 2, 3, 4, 6, 8].filter((k) => k * Math.max(h, w) <= 4096).map((k) => {
      const option = document.createElement("option");
      option.value = k; option.textContent = `${k * w} × ${k * h}${k === 1 ? " (this view's)" : ` (${k}×)`}`;
      return option;
    }));
    restore(editable);
  }

  function showRange(w) {  // a transfer function's window in data units ("auto": the volume's percentiles)
    return w === "auto" ? "auto" : w.map((v) => String(+v.toPrecision(4))).join(" … ");
  }

  function showModel() {
    const m = hello.model;
    $("model").textContent = `${m.shape.slice().reverse().join(" × ")} voxels, ${m.channels} channel(s), ` +
      `${m.wavelets.join(", ")}, ${m.coefficients.toLocaleString()} coefficients ` +
      (m.reading ? "(the file's most important; reading the rest…)" : m.failure ? "(the file's most important " +
       `only: the rest could not be read, ${m.failure})` : "kept") +
      (m.transfer_function ? `, classified with ${m.transfer_function}` : "") + values(m, editor.histogram) +
      modelError(m);
  }
  function values(m, h) {  // the input's range and the model's field against it (once)
    if (m.channels !== 1) return "";
    const r = (v) => v.map((x) => String(+x.toPrecision(4))).join(" … ");
    return (m.value_range ? `. Input values ${r(m.value_range)}` : ". Input values not known (a file written " +
            "before clwave kept them: classified as the model's field)") +
      (h && m.value_range ? `; the model's field ${r(h.field)}, classified clamped to the input's` : "");
  }
  function modelError(m) {  // a file's recorded error against its input (viewer.md §4), not the frames' error
    const e = m.error ? m.error.rms : null;
    const part = m.error && (!m.error.whole || m.reading || m.failure);  // the view holds fewer than the file's
    return ". The model's error against the input: " + (e !== null ? `RMS ${e.toPrecision(3)} of the largest ` +
      `value (PSNR ${(-20 * Math.log10(Math.max(e, 1e-30))).toFixed(1)} dB)` + (part ? ", the whole file's" : "") :
      m.error ? "not recorded in the file (clwave compress records it where it reads the input whole)" :
      "not known (a model made here, not read from a .clw)") +
      "; the frames' error is against the model's final image";
  }

  // ---------------------------------------------------------------- orbit, zoom, reset
  let drag = null;
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
  function showDetail() {
    const d = detailOf(+$("detail").value);
    $("detail-out").textContent = `${(100 * d).toFixed(d >= 0.1 ? 0 : d >= 0.01 ? 1 : 2)} %`;
    return d;
  }
  $("detail").addEventListener("input", () => { state.detail = showDetail(); request(); });
  // window sliders span 0 .. 2 x the auto window's top
  const span = () => 2 * Math.max(hello.window[1], 1e-30);
  // a colour bar's label: three digits, an exponent without its "+" and a mantissa without trailing zeros
  const short = (x) => x.toPrecision(3).replace(/(\.\d*?)0+(?=e|$)/, "$1").replace(/\.(?=e|$)/, "").replace("e+", "e");
  function showWindow() {  // the sliders, their figures and the colour bar's labels
    const [lo, hi] = state.window || hello.window;
    $("lo").value = Math.round(1000 * lo / span()); $("hi").value = Math.round(1000 * hi / span());
    $("lo-out").textContent = lo.toPrecision(3);
    $("hi-out").textContent = hi.toPrecision(3);
    $("bar-lo").textContent = short(lo); $("bar-hi").textContent = short(hi);
    $("bar-mid").textContent = short((lo + hi) / 2);
    // three labels of up to 7 characters need about 150 px: under the bar of a smaller image, the low and high alone
    // (which wrap, never run together, under a bar narrower than two)
    $("bar-mid").hidden = hello.size[1] < 200;
  }
  function drawColourBar() {  // the colour map's 256 rows (the hello's, base64 of RGB bytes) from low to high
    const rows = atob(hello.colour_maps[state.colour_map]), c = $("colour-bar").getContext("2d");
    const image = c.createImageData(256, 1);
    for (let i = 0; i < 256; i++) {
      for (let j = 0; j < 3; j++) image.data[4 * i + j] = rows.charCodeAt(3 * i + j);
      image.data[4 * i + 3] = 255;
    }
    c.putImageData(image, 0, 0);
  }
  const moveWindow = () => {
    const lo = span() * $("lo").value / 1000, hi = span() * $("hi").value / 1000;
    if (hi > lo) { state.window = [lo, hi]; showWindow(); request(); }
  };
  $("lo").addEventListener("input", moveWindow);
  $("hi").addEventListener("input", moveWindow);
  $("auto-window").addEventListener("click", () => { state.window = null; showWindow(); request(); });
  $("colour-map").addEventListener("change", (ev) => { state.colour_map = ev.target.value; drawColourBar(); request(); });
  $("shading").addEventListener("change", (ev) => { state.shading = ev.target.checked; request(); });
  // transfer function (a scalar model, classified while rendering): a base, a preset (null: the starting function,
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
  function through(points, anchor, back) {  // points seen through the sliders (back: the points seen, through them back)
    const mid = (anchor[0] + anchor[1]) / 2, shift = slider("tf-window") * (anchor[1] - anchor[0]);
    const k = slider("tf-width"), o = slider("tf-opacity");
    return points.map(([v, r, g, b, a]) => (back ? [mid + (v - mid - shift) / k, r, g, b, a / o] :
                                                   [mid + shift + (v - mid) * k, r, g, b, Math.min(MAX_OPACITY, a * o)]));
  }
  function sendTf(moving) {  // the function as the server gets it
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
  }
  const anchorNow = () => tf.base.anchor || editor.anchor;  // the base's window in data units, or null (not yet known)
  function showCentre() {  // the centre slider in data units: its span the input's range, its value the window's centre
    const a = anchorNow(), el = $("tf-window"), mid = a && (a[0] + a[1]) / 2 + slider("tf-window") * (a[1] - a[0]);
    const span = editor.histogram ? editor.histogram.range : a ? [mid - 2 * (a[1] - a[0]), mid + 2 * (a[1] - a[0])] : [0, 1];
    el.min = span[0]; el.max = span[1] > span[0] ? span[1] : span[0] + 1; el.step = "any";
    el.disabled = !a;
    if (a) el.value = mid;
    $("tf-window-out").textContent = a ? String(+mid.toPrecision(4)) : "";
  }
  function centreTo(value) {  // the window's centre moved to ``value`` (data units): the shift in the base's widths
    const a = anchorNow();
    if (!a || !(a[1] > a[0])) return false;
    const shift = (value - (a[0] + a[1]) / 2) / (a[1] - a[0]);
    tf.sliders["tf-window"] = Math.min(MAX_SHIFT, Math.max(-MAX_SHIFT, shift));
    return true;
  }
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
  function commit() {
    if (before !== null && before.tf !== JSON.stringify(tf)) {
      done.push(before); undone.length = 0;
      if (done.length > HISTORY) done.shift();
    }
    before = null;
    showHistory();
  }
  function showHistory() { $("tf-undo").disabled = !done.length; $("tf-redo").disabled = !undone.length; }
  function step(from, to) {
    if (!from.length || before !== null || tfCanvas.closest("fieldset:disabled")) return;
    to.push(seen());
    const back = from.pop();
    tf = JSON.parse(back.tf);
    Object.assign(editor, { axis: back.axis, top: back.top, window: back.window, anchor: back.anchor,
                            points: back.points });
    select(-1); sendTf(false); showHistory();
  }
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
  $("background").addEventListener("input", (ev) => {
    state.background = ev.target.value / 100; $("background-out").textContent = state.background.toFixed(2); request();
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

  function framePoints(points, window) {  // a preset's points and window as a frame was classified by them
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
  }

  function fitEditor(fresh) {
    const pts = editor.points, h = editor.histogram ? editor.histogram.range : [pts[0][0], pts[pts.length - 1][0]];
    let lo = Math.min(h[0], pts[0][0]), hi = Math.max(h[1], pts[pts.length - 1][0]);
    if (!fresh) { lo = Math.min(lo, editor.axis[0]); hi = Math.max(hi, editor.axis[1]); }
    editor.axis = hi > lo ? [lo, hi] : [lo - 0.5, lo + 0.5];
    const most = Math.max(...pts.map((p) => p[4]));
    if (fresh || most > editor.top) editor.top = 2 * most || 1;  // room to raise the opacity twofold
    editor.fresh = false;
  }

  function drawEditor() {
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
  }

  function edited(moving) {  // the points shown, edited, are the base through the sliders backwards
    const anchor = anchorNow();  // a preset's: the window its frame was classified by, without the sliders
    tf.base = { points: through(editor.points, anchor, true), anchor };
    if (stats.tfInput === null) stats.tfInput = performance.now();
    sendTf(moving);
  }

  function select(i) {
    editor.selected = i;
    const p = editor.points && editor.points[i];
    $("tf-colour").disabled = !p;
    if (p) $("tf-colour").value = "#" + p.slice(1, 4).map((x) => Math.round(255 * x).toString(16).padStart(2, "0")).join("");
    drawEditor();
  }

  function canvasAt(ev) {  // the pointer in canvas pixels (the canvas is scaled to the panel's width)
    const r = tfCanvas.getBoundingClientRect();
    return [(ev.clientX - r.left) * tfCanvas.width / r.width, (ev.clientY - r.top) * tfCanvas.height / r.height];
  }

  function hit(x, y) {  // the point within HIT pixels, nearest first; -1 for none
    let best = -1, near = HIT * HIT;
    (editor.points || []).forEach((p, i) => {
      const d = (xOf(p[0]) - x) ** 2 + (yOf(p[4]) - y) ** 2;
      if (d <= near) { best = i; near = d; }
    });
    return best;
  }

  function add(value, opacity) {  // a new point, coloured as the function is there; its index, or -1 (too near one)
    const pts = editor.points, gap = GAP * (editor.axis[1] - editor.axis[0]);
    const k = pts.findIndex((p) => p[0] > value), at = k < 0 ? pts.length : k;
    if (pts.length >= MAX_POINTS || (at > 0 && value - pts[at - 1][0] < gap) ||
        (at < pts.length && pts[at][0] - value < gap)) return -1;
    const a = pts[Math.max(0, at - 1)], b = pts[Math.min(pts.length - 1, at)];
    const t = b[0] > a[0] ? (value - a[0]) / (b[0] - a[0]) : 0;
    pts.splice(at, 0, [value, ...[1, 2, 3].map((j) => a[j] + t * (b[j] - a[j])), opacity]);
    return at;
  }

  function remove(i) {
    if (i < 0 || editor.points.length <= 2 || tfCanvas.closest("fieldset:disabled")) return;
    begin();
    editor.points.splice(i, 1);
    select(-1);
    edited(false);
    commit();
  }

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

  // ---------------------------------------------------------------- the clip of a shaded view (world units)
  // Sent with every shaded view (X-ray frames are splatted whole: none): a crop box of the content's world box (the
  // hello's), its sliders at their ends no box, and a plane: normal to an axis, or facing the camera (its normal the
  // view's direction, recomputed as the view turns), placed by its slider across the box (the view's: across its
  // bounding sphere). The server makes the clwave.Clip; one that keeps nothing is its line on the status line.
  const AXES = ["x", "y", "z"], STEPS = 1000;
  function clipOf() {
    const [lo, hi] = hello.model.box, at = (i, v) => lo[i] + (hi[i] - lo[i]) * v / STEPS;
    const ends = AXES.map((a, i) => [at(i, +$(`clip-${a}0`).value), at(i, +$(`clip-${a}1`).value)]);
    const cropped = AXES.some((a) => +$(`clip-${a}0`).value > 0 || +$(`clip-${a}1`).value < STEPS);
    const box = cropped ? [...ends.map((e) => e[0]), ...ends.map((e) => e[1])] : null;
    const planes = $("clip-plane").checked ? [plane(lo, hi, +$("clip-at").value / STEPS)] : [];
    return box || planes.length ? { box, planes } : null;
  }
  function plane(lo, hi, t) {  // [point, normal]: the normal towards what is kept
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
  }
  function showClip() {
    const [lo, hi] = hello.model.box, f = (x) => String(+x.toPrecision(3));
    AXES.forEach((a, i) => {
      const at = (v) => lo[i] + (hi[i] - lo[i]) * v / STEPS;
      $(`clip-${a}-out`).textContent = `${f(at(+$(`clip-${a}0`).value))} … ${f(at(+$(`clip-${a}1`).value))}`;
    });
    $("clip-at").disabled = !$("clip-plane").checked;
    $("clip-at-out").textContent = `${(100 * $("clip-at").value / STEPS).toFixed(0)} %`;
  }
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

  // ---------------------------------------------------------------- the page's state over a reload
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
                 detail: within(1e-3, 1), background: within(0, 1), shading: flag, scale_bar: flag,
                 fov: (x) => x === null || within(5, 120)(x), mode: (x) => hello.modes.includes(x),
                 colour_map: (x) => typeof x === "string" && Object.hasOwn(hello.colour_maps, x),
                 window: (x) => x === null || (Array.isArray(x) && x.length === 2 && x.every(finite) && x[0] < x[1]) };
  function keep() {
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
  }
  function forget() {
    history.replaceState(null, "", location.pathname + location.search);
    try { sessionStorage.removeItem(KEPT); } catch (e) { /* nothing kept */ }
  }
  function tfKept(t) {  // the kept transfer function (base and sliders), checked as the server checks what it makes
    const s = t && t.sliders, b = t && t.base;
    if (!s || !b || !within(-MAX_SHIFT, MAX_SHIFT)(s["tf-window"]) || !within(0, 100)(s["tf-width"]) ||
        !within(0, 100)(s["tf-opacity"])) return false;
    if (!b.points) return b.preset === null || hello.presets.includes(b.preset);
    const p = b.points, value = within(-1e30, 1e30), unit = within(0, 1);
    return Array.isArray(p) && p.length >= 2 && p.length <= MAX_POINTS && p.every((q, i) => Array.isArray(q) &&
      q.length === 5 && value(q[0]) && q.slice(1, 4).every(unit) && within(0, MAX_OPACITY)(q[4]) &&
      (!i || q[0] > p[i - 1][0])) && Array.isArray(b.anchor) && b.anchor.length === 2 && b.anchor.every(finite) &&
      b.anchor[0] < b.anchor[1];
  }
  function clipKept(c) {  // the clip's inputs: the sliders' steps, each low end below its high one, an axis offered
    const step = within(0, STEPS);
    return c && AXES.every((a) => step(c[`clip-${a}0`]) && step(c[`clip-${a}1`]) && c[`clip-${a}0`] < c[`clip-${a}1`]) &&
      step(c["clip-at"]) && flag(c["clip-plane"]) &&
      [...$("clip-axis").options].some((o) => o.value === c["clip-axis"]);
  }
  function restore(editable) {  // in setup: the kept view, where it is this model's, before the first view is sent
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
  }

  // ---------------------------------------------------------------- perspective (the server places the eye, frames.py)
  function showFov() { $("fov-out").textContent = `${$("fov").value}°`; }
  $("perspective").addEventListener("change", (ev) => {
    $("fov").disabled = !ev.target.checked; $("scale-bar").disabled = ev.target.checked;
    state.fov = ev.target.checked ? +$("fov").value : null; state.moving = false; request();
    state.scale_bar = $("scale-bar").checked && !ev.target.checked;
  });

  // ---------------------------------------------------------------- the scale bar over an orthographic view
  // Its length and label are the server's (the frame's scale_bar: --scale-bar's default for this extent, frames.py);
  // drawn here at the bottom right, white outlined in black as io/images.draw_scale_bar burns it into a saved image.
  function drawScaleBar() {
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
  }
  $("scale-bar").addEventListener("change", (ev) => { state.scale_bar = ev.target.checked; drawScaleBar(); keep(); });
  $("fov").addEventListener("input", () => { showFov(); state.fov = +$("fov").value; state.moving = true; request(); });
  $("fov").addEventListener("change", () => { state.moving = false; request(); });

  // ---------------------------------------------------------------- this view as a command, as Python, as an image
  // The server translates the view (clwave/view/export.py, the one home of it): the page sends its view and the
  // chosen size, and shows and copies the text, or downloads the image the server rendered at full quality.
  function exportSize() { const k = +$("export-scale").value || 1; return [k * canvas.height, k * canvas.width]; }
  async function exported(path) {
    const body = JSON.stringify({ view: { ...view(), moving: false }, size: exportSize() });
    const r = await fetch(`/${path}?token=${encodeURIComponent(token)}`, { method: "POST", body,
                                                                         headers: { "Content-Type": "application/json" } });
    if (!r.ok) throw new Error((await r.text()).trim() || `the server answered ${r.status}`);
    return r;
  }
  function exportNote(text, error = false) { $("export-note").textContent = text; $("export-note").classList.toggle("error", error); }
  async function copy(kind, what) {
    exportNote(`making the ${what}…`);
    try {
      const text = (await (await exported("export")).json())[kind], box = $("export-text");
      box.value = text; box.hidden = false; box.focus(); box.select();  // copied by Ctrl+C where the clipboard is not ours
      let copied = false;
      if (navigator.clipboard && window.isSecureContext) {
        try { await navigator.clipboard.writeText(text); copied = true; } catch (e) { copied = false; }
      }
      stats.exported = { kind, text };
      exportNote(copied ? `copied the ${what}` : `the ${what} is selected: Ctrl+C copies it`);
    } catch (e) { exportNote(e.message, true); }
  }
  $("copy-command").addEventListener("click", () => copy("command", "command line"));
  $("copy-python").addEventListener("click", () => copy("python", "Python"));
  $("save-image").addEventListener("click", async () => {
    const [h, w] = exportSize();
    exportNote(`rendering ${w} × ${h} at full quality…`);
    try {
      const blob = await (await exported("image")).blob(), a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = `clwave_${state.mode}_az${state.azimuth.toFixed(0)}_el${state.elevation.toFixed(0)}_${w}x${h}.png`;
      a.click();
      setTimeout(() => URL.revokeObjectURL(a.href), 1000);
      stats.saved = { size: [h, w], blob };
      exportNote(`saved ${w} × ${h}`);
    } catch (e) { exportNote(e.message, true); }
  });

  // ---------------------------------------------------------------- figures and saving
  const fmt = (x, d = 3) => (typeof x === "number" ? x.toPrecision(d) : String(x));
  // a frame short of final: what it waits for (an X-ray's prefix, a shaded coarse frame's "reading" or "set-up")
  const waitingWords = (f) => f.prefix ? "refined from the file's most important part; the rest is being read…"
    : f.waiting === "reading" ? `coarse (detail ${f.detail}) while the rest of the file is read…`
    : f.waiting === "set-up" ? `coarse (detail ${f.detail}) while the ray tracer is set up…` : "refining…";
  function showFigures(f) {
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
  }
  $("save").addEventListener("click", () => {
    if (!current || !current.fig.final) return;
    const a = document.createElement("a"), f = current.fig;
    a.href = URL.createObjectURL(current.blob);
    a.download = `clwave_${f.mode}_az${f.azimuth.toFixed(0)}_el${f.elevation.toFixed(0)}.png`;
    a.click();
    setTimeout(() => URL.revokeObjectURL(a.href), 1000);
  });
})();
