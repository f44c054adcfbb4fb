// clwave viewer page (docs/viewer.md §4): sends its whole view on every change, shows the frames of the latest.
"use strict";
(() => {
  const $ = (id) => document.getElementById(id);
  const token = new URLSearchParams(location.search).get("token") || "";
  const canvas = $("image"), ctx = canvas.getContext("2d"), status = $("status");
  const HOME = { azimuth: 30, elevation: 20, zoom: 1 };
  const state = { ...HOME, mode: "xray", detail: 1, window: null, moving: false, background: 0, shading: true,
                  tf: null };
  let sentSeq = 0, hello = null, current = null, pending = false, idleTimer = null;
  // what the tests and tools/bench.py read: frames received, shown, dropped as superseded; times in ms
  const stats = { received: 0, shown: 0, dropped: 0, firstImage: null, released: null, tfInput: null, frames: [] };
  window.clwave = { state, stats, send: () => request(), current: () => current,
                    latest: () => (pending || held ? -1 : sentSeq) };  // the view asked for last (-1: one is on its way)

  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws?token=` +
                           encodeURIComponent(token));
  ws.binaryType = "arraybuffer";
  ws.onclose = (ev) => { status.textContent = `disconnected (${ev.code}${ev.reason ? ": " + ev.reason : ""})`;
                         status.classList.add("error"); };
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
    ws.send(JSON.stringify({ type: "view", seq: sentSeq, ...state }));
  }
  function request() {  // at most one message per 16 ms: the latest state then
    if (!pending) { pending = true; setTimeout(send, 16); }
  }

  function onText(msg) {
    if (msg.type === "hello") { hello = msg; setup(); request(); }
    else if (msg.type === "model") { hello.model = msg.model; showModel(); }  // a file's whole model is in
    else if (msg.type === "status" && msg.seq === sentSeq) status.textContent = msg.message;
    else if (msg.type === "error" && msg.seq === sentSeq) {
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
    });
  }
  function next(fig) {  // a drag's frame has come: its next view goes at once
    if (fig.seq === awaiting) { awaiting = 0; if (held) send(); }
  }

  function setup() {
    const [h, w] = hello.size;
    canvas.width = w; canvas.height = h;
    showModel();
    const shaded = hello.modes.includes("shaded");
    document.querySelector('input[value="shaded"]').disabled = !shaded;
    $("shaded-note").textContent = shaded ? "" : "shaded needs a scalar or a classified (RGBA) model";
    // the first entry is the transfer function the server starts from (given with --tf/--tf-window, the model's
    // own, or grey; preset null), then the presets with their own windows
    const start = hello.tf || { name: "grey", window: "auto" };
    $("tf-preset").replaceChildren(...[null, ...hello.presets].map((name) => {
      const option = document.createElement("option");
      option.value = name || "";
      option.textContent = name || `${start.name || "custom"}, window ${showRange(start.window)} (start)`;
      return option;
    }));
    const tf = shaded && hello.capabilities.shaded.tf;
    $("tf").disabled = !tf;
    $("tf-note").textContent = tf ? "classified while rendering" : "the model was classified before its " +
      "transform (RGBA): lighting and background act";
    $("tf-range").textContent = showRange(start.window);
    if (tf) { state.tf = { preset: null, centre: 0, width: 1, opacity: 1 }; showTf(); }
    syncMode();
    showDetail(); showWindow();
  }

  function showRange(w) {  // a transfer function's window in data units ("auto": the volume's percentiles)
    return w === "auto" ? "auto" : w.map((v) => String(+v.toPrecision(4))).join(" … ");
  }

  function showModel() {
    const m = hello.model;
    $("model").textContent = `${m.shape.slice().reverse().join(" × ")} voxels, ${m.channels} channel(s), ` +
      `${m.wavelets.join(", ")}, ${m.coefficients.toLocaleString()} coefficients ` +
      (m.reading ? "(the file's most important; reading the rest…)" : "kept") +
      (m.transfer_function ? `, classified with ${m.transfer_function}` : "");
  }

  // ---------------------------------------------------------------- orbit, zoom, reset
  let drag = null;
  canvas.addEventListener("pointerdown", (ev) => {
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
    state.zoom = Math.max(0.1, Math.min(50, state.zoom * Math.exp(-0.0015 * ev.deltaY)));
    state.moving = true;
    request();
    clearTimeout(idleTimer);
    idleTimer = setTimeout(() => { state.moving = false; request(); }, 200);
  }, { passive: false });
  canvas.addEventListener("dblclick", () => { Object.assign(state, HOME, { moving: false }); request(); });

  // ---------------------------------------------------------------- controls
  const syncMode = () => {
    $("xray-controls").disabled = state.mode !== "xray";
    $("shaded-controls").disabled = state.mode !== "shaded";
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
  function showWindow() {
    const [lo, hi] = state.window || hello.window;
    $("lo").value = Math.round(1000 * lo / span()); $("hi").value = Math.round(1000 * hi / span());
    $("lo-out").textContent = lo.toPrecision(3); $("hi-out").textContent = hi.toPrecision(3);
  }
  const moveWindow = () => {
    const lo = span() * $("lo").value / 1000, hi = span() * $("hi").value / 1000;
    if (hi > lo) { state.window = [lo, hi]; showWindow(); request(); }
  };
  $("lo").addEventListener("input", moveWindow);
  $("hi").addEventListener("input", moveWindow);
  $("auto-window").addEventListener("click", () => { state.window = null; showWindow(); request(); });
  $("shading").addEventListener("change", (ev) => { state.shading = ev.target.checked; request(); });
  // transfer function (a scalar model, classified while rendering): a slider being moved asks for the cheap
  // frames of a drag, its release for the refined view
  const TF_SLIDERS = { "tf-window": ["centre", (v) => (v - 50) / 50], "tf-width": ["width", (v) => 10 ** ((v - 50) / 50)],
                       "tf-opacity": ["opacity", (v) => 10 ** ((v - 50) / 25)] };
  function showTf() {
    for (const [id, [key]] of Object.entries(TF_SLIDERS)) $(id + "-out").textContent = state.tf[key].toPrecision(2);
  }
  for (const [id, [key, of]] of Object.entries(TF_SLIDERS)) {
    $(id).addEventListener("input", (ev) => {
      state.tf = { ...state.tf, [key]: of(+ev.target.value) }; state.moving = true; showTf(); request();
      if (stats.tfInput === null) stats.tfInput = performance.now();
    });
    $(id).addEventListener("change", () => { state.moving = false; request(); });
  }
  $("tf-preset").addEventListener("change", (ev) => {
    state.tf = { ...state.tf, preset: ev.target.value || null }; request();
  });
  $("background").addEventListener("input", (ev) => {
    state.background = ev.target.value / 100; $("background-out").textContent = state.background.toFixed(2); request();
  });

  // ---------------------------------------------------------------- figures and saving
  const fmt = (x, d = 3) => (typeof x === "number" ? x.toPrecision(d) : String(x));
  function showFigures(f) {
    const rows = [["view", `az ${f.azimuth.toFixed(1)}°, el ${f.elevation.toFixed(1)}°`],
                  ["image", `${f.width} × ${f.height}${f.final ? ", final" : ""}`]];
    if (f.mode === "xray") {
      rows.push(["coefficients", `${f.coefficients.toLocaleString()} (${(100 * f.fraction).toPrecision(3)} %)`]);
      rows.push(["error estimate", `${fmt(f.error)} (${f.error_kind})`]);
    } else {
      rows.push(["tolerance", `${fmt(f.tolerance)}, detail ${f.detail}` +
                 (f.reduction > 1 ? `, 1/${f.reduction} size` : "")]);
      if (f.error !== null) rows.push(["error estimate", `${fmt(f.error)} (${f.error_kind})`]);
      if (f.tf_window) $("tf-range").textContent = showRange(f.tf_window);  // the window this frame was classified by
    }
    rows.push(["frame", `${(1000 * f.seconds).toFixed(0)} ms render, ${(1000 * f.elapsed).toFixed(0)} ms since view`]);
    const table = $("figures");
    table.replaceChildren(...rows.map(([k, v]) => {
      const tr = document.createElement("tr");
      for (const text of [k, v]) { const td = document.createElement("td"); td.textContent = text; tr.append(td); }
      return tr;
    }));
    status.classList.remove("error");
    status.textContent = f.note ? f.note : f.final ? "refined" : state.moving ? "moving" : f.prefix ? "refined from the file's most " +
      "important part; the rest is being read…" : "refining…";
    $("save").disabled = !(f.final && f.mime === "image/png");
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
