// This view as a command, as Python, as an image.
"use strict";
// The server translates the view (clwave/view/export.py, the one home of it): the page sends its view and the
// chosen size, and shows and copies the text, or downloads the image the server rendered at full quality.
const exportSize = () => { const k = +$("export-scale").value || 1; return [k * canvas.height, k * canvas.width]; };
const exported = async (path) => {
  const body = JSON.stringify({ view: { ...view(), moving: false }, size: exportSize() });
  const r = await fetch(`/${path}?token=${encodeURIComponent(token)}`, { method: "POST", body,
                                                                       headers: { "Content-Type": "application/json" } });
  if (!r.ok) throw new Error((await r.text()).trim() || `the server answered ${r.status}`);
  return r;
};
const exportNote = (text, error = false) => {
  $("export-note").textContent = text; $("export-note").classList.toggle("error", error);
};
const copy = async (kind, what) => {
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
};
$("copy-command").addEventListener("click", () => copy("command", "command line"));
$("copy-python").addEventListener("click", () => copy("python", "Python"));
$("save-image").addEventListener("click", async () => {
  const [h, w] = exportSize();
  exportNote(`rendering ${w} × ${h} at full quality…`);
  try {
    const r = await exported("image"), blob = await r.blob(), a = document.createElement("a");
    const header = r.headers.get("X-Clwave-Note"), note = header && JSON.parse(header);  // the renderer's warnings
    a.href = URL.createObjectURL(blob);
    a.download = `clwave_${state.mode}_az${state.azimuth.toFixed(0)}_el${state.elevation.toFixed(0)}_${w}x${h}.png`;
    a.click();
    setTimeout(() => URL.revokeObjectURL(a.href), 1000);
    stats.saved = { size: [h, w], blob, note };
    exportNote(`saved ${w} × ${h}` + (note ? `; the renderer warned: ${note}` : ""), !!note);
  } catch (e) { exportNote(e.message, true); }
});
