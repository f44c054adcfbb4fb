// clwave viewer page (docs/viewer.md §4): sends its whole view on every change, shows the frames of the latest.
// The socket, its messages and the page's set-up; index.html loads the other scripts first.
"use strict";
let sentSeq = 0, hello = null, pending = false, closed = false;
window.clwave = { state, stats, send: () => request(), current: () => current, view: () => view(),
                  latest: () => (pending || held ? -1 : sentSeq) };  // the view asked for last (-1: one is on its way)

// While dragging, one view at a time is on its way: the next is sent when its frame arrives (or after a
// second), so every frame rendered is of the view asked for last and none is dropped; a still view is sent
// at once (the server abandons what it was refining).
let awaiting = 0, since = 0, held = false;
const send = () => {
  pending = false;
  if (ws.readyState !== WebSocket.OPEN) return;
  if (state.moving && awaiting && performance.now() - since < 1000) { held = true; return; }  // sent with the frame
  held = false;
  sentSeq += 1;
  awaiting = state.moving ? sentSeq : 0;
  since = performance.now();
  ws.send(JSON.stringify(view()));
  if (!state.moving) keep();
};
// The socket closed: the server refused a message of this page (policy, size: the page may be reloaded) or this
// tab (as many are open as it serves), or it stopped or cannot be reached. Nothing answers any more: every control
// that sends is disabled (greyed), the last image stays (and can still be saved), and the status line says what
// happened and what to do.
const REFUSED = [1008, 1009], BUSY = 1013;  // protocol.POLICY, TOO_BIG; server.MAX_TABS open (its reason says)
const disconnected = (ev) => {
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
};
const view = () => {  // the message of the view now: a shaded one with its clip (X-ray frames are splatted whole)
  return { type: "view", seq: sentSeq, ...state, clip: hello && state.mode === "shaded" ? clipOf() : null };
};
const request = () => {  // at most one message per 16 ms: the latest state then
  if (!pending) { pending = true; setTimeout(send, 16); }
};

const onText = (msg) => {
  if (msg.type === "hello") { hello = msg; setup(); request(); }
  else if (msg.type === "model") { hello.model = msg.model; showModel(); }  // a file's whole model is in
  else if (msg.type === "histogram") { editor.histogram = msg; drawEditor(); showCentre(); showModel(); }
  else if (msg.type === "status" && msg.seq === sentSeq) status.textContent = msg.message;
  else if (msg.type === "error" && (msg.seq === undefined || msg.seq === sentSeq)) {  // no seq: the server's, not a view's
    status.textContent = msg.message; status.classList.add("error");
    next(msg);
  }
};
const next = (fig) => {  // a drag's frame has come: its next view goes at once
  if (fig.seq === awaiting) { awaiting = 0; if (held) send(); }
};

const setup = () => {
  const [h, w] = hello.size;
  canvas.width = overlay.width = w; canvas.height = overlay.height = h;
  Object.assign(state, Object.assign(HOME, hello.home));  // the model's opening view: a slab's face
  showModel();
  setupViews();
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
};

// opened last: its messages reach every script's functions
const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws?token=` +
                         encodeURIComponent(token));
ws.binaryType = "arraybuffer";
ws.onclose = disconnected;
ws.onmessage = (ev) => (typeof ev.data === "string" ? onText(JSON.parse(ev.data)) : onFrame(ev.data));
