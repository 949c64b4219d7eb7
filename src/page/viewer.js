"use strict";
/*
 * The comparison viewer.
 *
 * Images arrive in the JSON block #fog-data: {width, height, images: [{label, png}]}, where
 * images[0] is the reference and `png` is a base64 greyscale PNG of 2W x 2H holding the
 * image's Radiance RGBE bytes as four planes:  R G / B E.  A pixel's linear value is
 * (mantissa + 0.5) * 2^(E - 136), and E = 0 means black. An opaque greyscale PNG decoded with
 * colorSpaceConversion 'none' reaches getImageData unchanged, so the floats come back exactly
 * as the page's writer encoded them.
 *
 * Both views are canvases the size of their box in device pixels. Each redraw copies the
 * source canvas (the tone-mapped image, or the false-colour error) with smoothing off, at
 * `zoom` device pixels per image pixel (an integer from 1 up) and at an origin rounded to whole
 * device pixels, so magnified pixels are exact squares. Both views share zoom and the image
 * point at their centre, so they pan and zoom together.
 */
(function () {
  const data = JSON.parse(document.getElementById("fog-data").textContent);
  const W = data.width, H = data.height;
  const images = data.images;            // [{label, png}]; images[0] is the reference
  const N = images.length;
  const $ = (id) => document.getElementById(id);
  const viewer = $("viewer");

  // ---- State ---------------------------------------------------------------------------
  const state = {
    current: 0,                 // image shown in the image view (0 = the reference)
    errorOf: N > 1 ? 1 : 0,     // estimator whose error the error view shows
    exposure: 0,                // stops, applied to linear values before sRGB encoding
    zoom: 1,                    // device pixels per image pixel
    cx: W / 2, cy: H / 2,       // image point at the centre of the views
    fit: true,                  // refit on resize until the user zooms or pans
    showError: N > 1,
    metric: "smape",            // "smape" or "relative"
    range: 0,                   // index into RANGES
    hover: null,                // [x, y]: image pixel under the pointer, or null
  };
  // Until the images are decoded, keys, clicks and controls only change `state` (nothing can be
  // painted yet); once they are, everything is painted from `state`, so no input is lost.
  let decoded = false;
  const linear = new Array(N);            // Float32Array(W * H * 3) per image, once decoded
  const errorValues = new Float32Array(W * H);

  // Colour scales of the error view: logarithmic from 10^lo to 10^hi, or linear from 0 to hi.
  const RANGES = [
    { log: true, lo: -3, hi: 0 },
    { log: true, lo: -4, hi: 0 },
    { log: true, lo: -2, hi: 0 },
    { log: true, lo: -3, hi: 1 },
    { log: true, lo: -2, hi: 1 },
    { log: false, hi: 1 },
    { log: false, hi: 0.25 },
    { log: false, hi: 0.05 },
  ];
  const METRIC_NAMES = { smape: "SMAPE", relative: "relative error" };

  // ---- RGBE decoding --------------------------------------------------------------------
  // 2^(E - 136) for each exponent byte; 0 for E = 0 (black).
  const RGBE_FACTOR = new Float64Array(256);
  for (let e = 1; e < 256; e++) RGBE_FACTOR[e] = Math.pow(2, e - 136);

  function base64Bytes(text) {
    const binary = atob(text);
    const bytes = new Uint8Array(binary.length);
    for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
    return bytes;
  }

  async function decodeImage(base64) {
    const blob = new Blob([base64Bytes(base64)], { type: "image/png" });
    let bitmap;
    try {
      bitmap = await createImageBitmap(blob, { premultiplyAlpha: "none", colorSpaceConversion: "none" });
    } catch (_) {
      bitmap = await createImageBitmap(blob);    // browsers without the options
    }
    if (bitmap.width !== 2 * W || bitmap.height !== 2 * H) {
      throw new Error("an image is " + bitmap.width + "x" + bitmap.height + ", not " + 2 * W + "x" + 2 * H);
    }
    const canvas = document.createElement("canvas");
    canvas.width = 2 * W;
    canvas.height = 2 * H;
    const ctx = canvas.getContext("2d", { willReadFrequently: true });
    ctx.drawImage(bitmap, 0, 0);
    if (bitmap.close) bitmap.close();
    const grey = ctx.getImageData(0, 0, 2 * W, 2 * H).data;   // RGBA; grey in R, G and B
    const out = new Float32Array(W * H * 3);
    const right = 4 * W;          // bytes from a plane to the plane on its right
    const down = 8 * W * H;       // bytes from a plane to the plane below it
    for (let y = 0; y < H; y++) {
      for (let x = 0; x < W; x++) {
        const p = (y * 2 * W + x) * 4;
        const f = RGBE_FACTOR[grey[p + down + right]];
        const o = (y * W + x) * 3;
        out[o] = (grey[p] + 0.5) * f;
        out[o + 1] = (grey[p + right] + 0.5) * f;
        out[o + 2] = (grey[p + down] + 0.5) * f;
      }
    }
    return out;
  }

  // ---- Source canvases: the tone-mapped image and the false-colour error -----------------
  function makeCanvas(w, h) {
    const c = document.createElement("canvas");
    c.width = w;
    c.height = h;
    return c;
  }
  const shownCanvas = makeCanvas(W, H);
  const errorCanvas = makeCanvas(W, H);

  // sRGB encoding of [0, 1], tabulated finely enough that no 8-bit level is lost near black.
  const LUT_SIZE = 1 << 16;
  const SRGB = new Uint8ClampedArray(LUT_SIZE + 1);
  for (let i = 0; i <= LUT_SIZE; i++) {
    const v = i / LUT_SIZE;
    SRGB[i] = Math.round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055));
  }

  function paintShown() {
    if (!decoded) return;
    const values = linear[state.current];
    const ctx = shownCanvas.getContext("2d");
    const img = ctx.createImageData(W, H);
    const px = img.data;
    const scale = Math.pow(2, state.exposure) * LUT_SIZE;
    for (let p = 0, o = 0; p < W * H; p++, o += 3) {
      for (let c = 0; c < 3; c++) {
        const t = values[o + c] * scale;            // NaN and negatives fail `t > 0`: black
        px[4 * p + c] = SRGB[t > 0 ? (t < LUT_SIZE ? (t + 0.5) | 0 : LUT_SIZE) : 0];
      }
      px[4 * p + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
  }

  // Viridis, interpolated from nine samples of matplotlib's map.
  const VIRIDIS_STOPS = [
    [68, 1, 84], [71, 45, 123], [59, 82, 139], [44, 114, 142], [33, 144, 140],
    [39, 173, 129], [93, 200, 99], [170, 220, 50], [253, 231, 37],
  ];
  const VIRIDIS = new Uint8ClampedArray(256 * 3);
  for (let i = 0; i < 256; i++) {
    const t = (i / 255) * (VIRIDIS_STOPS.length - 1);
    const k = Math.min(Math.floor(t), VIRIDIS_STOPS.length - 2);
    const f = t - k;
    for (let c = 0; c < 3; c++) {
      VIRIDIS[3 * i + c] = Math.round(VIRIDIS_STOPS[k][c] * (1 - f) + VIRIDIS_STOPS[k + 1][c] * f);
    }
  }

  // Per-pixel error, mean over RGB: SMAPE |e-r|/(|e|+|r|) (a term with both zero counts 0),
  // or the relative error |e-r|/(r+0.01).
  function pixelError(e, r, o) {
    let sum = 0;
    for (let c = 0; c < 3; c++) {
      const d = Math.abs(e[o + c] - r[o + c]);
      if (state.metric === "smape") {
        const s = Math.abs(e[o + c]) + Math.abs(r[o + c]);
        if (s > 0) sum += d / s;
      } else {
        sum += d / (Math.abs(r[o + c]) + 0.01);
      }
    }
    return sum / 3;
  }

  // Position of an error value on the colour scale, 0..1.
  function scalePosition(v) {
    const r = RANGES[state.range];
    let t;
    if (r.log) t = v > 0 ? (Math.log10(v) - r.lo) / (r.hi - r.lo) : 0;
    else t = v / r.hi;
    return t > 0 ? (t < 1 ? t : 1) : 0;
  }

  function computeError() {
    if (!decoded) return;
    const e = linear[state.errorOf], r = linear[0];
    for (let p = 0; p < W * H; p++) errorValues[p] = pixelError(e, r, 3 * p);
  }

  function paintError() {
    if (!decoded) return;
    const ctx = errorCanvas.getContext("2d");
    const img = ctx.createImageData(W, H);
    const px = img.data;
    for (let p = 0; p < W * H; p++) {
      const i = Math.round(scalePosition(errorValues[p]) * 255) * 3;
      px[4 * p] = VIRIDIS[i];
      px[4 * p + 1] = VIRIDIS[i + 1];
      px[4 * p + 2] = VIRIDIS[i + 2];
      px[4 * p + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    paintColorbar();
  }

  function superscript(k) {
    const digits = "⁰¹²³⁴⁵⁶⁷⁸⁹";
    return (k < 0 ? "⁻" : "") + String(Math.abs(k)).split("").map((d) => digits[+d]).join("");
  }

  function paintColorbar() {
    const bar = $("colorbar");
    const ctx = bar.getContext("2d");
    const img = ctx.createImageData(256, 1);
    for (let i = 0; i < 256; i++) {
      for (let c = 0; c < 3; c++) img.data[4 * i + c] = VIRIDIS[3 * i + c];
      img.data[4 * i + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    // Tick labels: every decade on a log scale, quarters on a linear one.
    const r = RANGES[state.range];
    const ticks = $("ticks");
    ticks.textContent = "";
    const labels = [];
    if (r.log) {
      for (let k = r.lo; k <= r.hi; k++) {
        const text = k >= -2 && k <= 2 ? String(Math.pow(10, k).toFixed(Math.max(0, -k))) : "10" + superscript(k);
        labels.push([(k - r.lo) / (r.hi - r.lo), text]);
      }
    } else {
      for (let q = 0; q <= 4; q++) labels.push([q / 4, String(+(r.hi * q / 4).toPrecision(3))]);
    }
    for (const [t, text] of labels) {
      const span = document.createElement("span");
      span.style.left = (100 * t) + "%";
      span.textContent = text;
      ticks.appendChild(span);
    }
  }

  function rangeName(r) {
    if (r.log) return "log  10" + superscript(r.lo) + " … " + (r.hi === 0 ? "1" : "10" + superscript(r.hi));
    return "linear  0 … " + r.hi;
  }

  // ---- Views ---------------------------------------------------------------------------
  const views = [
    { figure: $("image-view"), source: shownCanvas },
    { figure: $("error-view"), source: errorCanvas },
  ];
  for (const v of views) {
    v.canvas = v.figure.querySelector("canvas.view-canvas");
    v.ctx = v.canvas.getContext("2d");
  }
  const visibleViews = () => views.filter((v, i) => i === 0 || state.showError);

  // Zoom levels: halvings of sqrt(2) below 1, integers from 1 up.
  const ZOOMS = [];
  for (let k = 10; k >= 1; k--) ZOOMS.push(Math.pow(2, -k / 2));
  ZOOMS.push(1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 48, 64);

  function stepZoom(z, dir) {
    if (dir > 0) return ZOOMS.find((l) => l > z * 1.0001) || ZOOMS[ZOOMS.length - 1];
    for (let i = ZOOMS.length - 1; i >= 0; i--) if (ZOOMS[i] < z * 0.9999) return ZOOMS[i];
    return ZOOMS[0];
  }

  // Device-pixel position of the image's top-left corner in a view.
  function origin(v) {
    return [
      Math.round(v.canvas.width / 2 - state.cx * state.zoom),
      Math.round(v.canvas.height / 2 - state.cy * state.zoom),
    ];
  }

  function resizeCanvases() {
    const dpr = window.devicePixelRatio || 1;
    // Make the views as high as the image at the zoom that fits their width (plus a margin),
    // within 240 px and 78 % of the window, so that little of them is empty.
    const across = views[0].canvas.getBoundingClientRect().width * dpr / W;
    const z = across >= 1 ? Math.floor(across) : across;
    const high = Math.min(Math.max(240, 0.78 * window.innerHeight), Math.max(240, (H * z) / dpr + 40));
    for (const v of views) v.canvas.style.height = Math.round(high) + "px";
    for (const v of visibleViews()) {
      const rect = v.canvas.getBoundingClientRect();
      const w = Math.max(1, Math.round(rect.width * dpr)), h = Math.max(1, Math.round(rect.height * dpr));
      if (v.canvas.width !== w || v.canvas.height !== h) {
        v.canvas.width = w;
        v.canvas.height = h;
      }
    }
    if (state.fit) fit();
  }

  function fit() {
    const c = views[0].canvas;
    const z = Math.min(c.width / W, c.height / H);
    state.zoom = z >= 1 ? Math.floor(z) : z;
    state.cx = W / 2;
    state.cy = H / 2;
    state.fit = true;
  }

  function clampCentre() {
    state.cx = Math.min(Math.max(state.cx, 0), W);
    state.cy = Math.min(Math.max(state.cy, 0), H);
  }

  function draw() {
    const z = state.zoom;
    for (const v of visibleViews()) {
      const ctx = v.ctx;
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.imageSmoothingEnabled = false;
      ctx.fillStyle = "#08090b";
      ctx.fillRect(0, 0, v.canvas.width, v.canvas.height);
      if (!decoded) continue;
      const [ox, oy] = origin(v);
      ctx.drawImage(v.source, ox, oy, W * z, H * z);
      if (state.hover) drawMarker(ctx, ox + state.hover[0] * z, oy + state.hover[1] * z, z);
    }
    $("zoom-value").textContent = state.zoom >= 1 ? state.zoom + "×" : state.zoom.toFixed(2) + "×";
  }

  // The pixel under the pointer, in both views: a square outline when zoomed in, else a cross.
  function drawMarker(ctx, x, y, z) {
    ctx.lineWidth = 1;
    if (z >= 4) {
      ctx.strokeStyle = "#000";
      ctx.strokeRect(x - 0.5, y - 0.5, z + 1, z + 1);
      ctx.strokeStyle = "#fff";
      ctx.strokeRect(x + 0.5, y + 0.5, z - 1, z - 1);
    } else {
      const cx = Math.round(x + z / 2) + 0.5, cy = Math.round(y + z / 2) + 0.5;
      ctx.strokeStyle = "#fff";
      ctx.beginPath();
      ctx.moveTo(cx - 9, cy); ctx.lineTo(cx - 3, cy);
      ctx.moveTo(cx + 3, cy); ctx.lineTo(cx + 9, cy);
      ctx.moveTo(cx, cy - 9); ctx.lineTo(cx, cy - 3);
      ctx.moveTo(cx, cy + 3); ctx.lineTo(cx, cy + 9);
      ctx.stroke();
    }
  }

  // Device-pixel position of a pointer event in a view's canvas.
  function devicePoint(v, e) {
    const rect = v.canvas.getBoundingClientRect();
    return [(e.clientX - rect.left) * (v.canvas.width / rect.width), (e.clientY - rect.top) * (v.canvas.height / rect.height)];
  }

  // Zoom one level in or out, keeping the image point at device point (mx, my) of view v.
  function zoomAbout(v, mx, my, dir) {
    const [ox, oy] = origin(v);
    const ix = (mx - ox) / state.zoom, iy = (my - oy) / state.zoom;
    state.zoom = stepZoom(state.zoom, dir);
    state.cx = ix - (mx - v.canvas.width / 2) / state.zoom;
    state.cy = iy - (my - v.canvas.height / 2) / state.zoom;
    state.fit = false;
    clampCentre();
    draw();
  }

  function zoomCentre(dir) {
    const c = views[0].canvas;
    zoomAbout(views[0], c.width / 2, c.height / 2, dir);
  }

  let drag = null;
  let wheel = 0;
  for (const v of views) {
    const c = v.canvas;
    c.addEventListener("pointerdown", (e) => {
      if (e.button !== 0) return;
      const rect = c.getBoundingClientRect();
      drag = { id: e.pointerId, x: e.clientX, y: e.clientY, cx: state.cx, cy: state.cy, ratio: c.width / rect.width };
      c.setPointerCapture(e.pointerId);
      c.classList.add("dragging");
    });
    c.addEventListener("pointermove", (e) => {
      if (drag && drag.id === e.pointerId) {
        state.cx = drag.cx - ((e.clientX - drag.x) * drag.ratio) / state.zoom;
        state.cy = drag.cy - ((e.clientY - drag.y) * drag.ratio) / state.zoom;
        state.fit = false;
        clampCentre();
      }
      setHover(v, e);
    });
    const endDrag = () => {
      drag = null;
      c.classList.remove("dragging");
    };
    c.addEventListener("pointerup", endDrag);
    c.addEventListener("pointercancel", endDrag);
    c.addEventListener("pointerleave", () => {
      if (drag) return;
      state.hover = null;
      updateReadout();
      draw();
    });
    c.addEventListener("wheel", (e) => {
      e.preventDefault();
      // One zoom step per notch; small trackpad deltas add up to one.
      wheel += e.deltaY * (e.deltaMode === 1 ? 33 : e.deltaMode === 2 ? 100 : 1);
      if (Math.abs(wheel) < 50) return;
      const [mx, my] = devicePoint(v, e);
      zoomAbout(v, mx, my, wheel < 0 ? 1 : -1);
      wheel = 0;
      setHover(v, e);
    }, { passive: false });
    c.addEventListener("dblclick", () => {
      fit();
      draw();
    });
  }

  function setHover(v, e) {
    const [mx, my] = devicePoint(v, e);
    const [ox, oy] = origin(v);
    const x = Math.floor((mx - ox) / state.zoom), y = Math.floor((my - oy) / state.zoom);
    state.hover = x >= 0 && y >= 0 && x < W && y < H ? [x, y] : null;
    updateReadout();
    draw();
  }

  // ---- Pixel readout -------------------------------------------------------------------
  function num(v) {
    if (v === 0) return "0";
    const a = Math.abs(v);
    return a >= 1e4 || a < 1e-3 ? v.toExponential(3) : v.toPrecision(4);
  }

  function span(text, cls) {
    const s = document.createElement(cls === "b" ? "b" : "span");
    if (cls && cls !== "b") s.className = cls;
    s.textContent = text;
    return s;
  }

  function rgbItem(label, values, o) {
    const item = document.createElement("span");
    const sw = span("", "swatch");
    const scale = Math.pow(2, state.exposure) * LUT_SIZE;
    const enc = (c) => SRGB[Math.max(0, Math.min(LUT_SIZE, Math.round(values[o + c] * scale))) || 0];
    sw.style.backgroundColor = "rgb(" + enc(0) + "," + enc(1) + "," + enc(2) + ")";
    item.append(sw, span(label, "b"), " " + num(values[o]) + "  " + num(values[o + 1]) + "  " + num(values[o + 2]));
    return item;
  }

  function updateReadout() {
    const out = $("readout");
    out.textContent = "";
    const marker = $("marker");
    if (!state.hover || !decoded) {
      marker.hidden = true;
      out.append("Point at an image to read its linear RGB values here.");
      return;
    }
    const [x, y] = state.hover;
    const p = y * W + x;
    out.append(span("x " + x + "  y " + y, "b"));
    if (state.current !== 0) out.append(rgbItem(images[state.current].label, linear[state.current], 3 * p));
    out.append(rgbItem(images[0].label, linear[0], 3 * p));
    if (N > 1) {
      const item = document.createElement("span");
      item.append(span(METRIC_NAMES[state.metric] + " of " + images[state.errorOf].label, "b"), " " + num(errorValues[p]));
      out.append(item);
      marker.hidden = !state.showError;
      marker.style.left = (100 * scalePosition(errorValues[p])) + "%";
    }
  }

  // ---- Selection, exposure, error settings ---------------------------------------------
  const buttons = Array.from(document.querySelectorAll(".choices button"));
  const rows = [];   // table rows whose first cell names an image: [row, index]
  for (const row of document.querySelectorAll("#results tr")) {
    const first = row.firstElementChild;
    if (!first || first.tagName === "TH" && first.getAttribute("scope") === "col") continue;
    const i = images.findIndex((im) => im.label === first.textContent.trim());
    if (i < 0) continue;
    row.classList.add("selectable");
    row.addEventListener("click", () => {
      select(i);
      viewer.scrollIntoView({ behavior: "smooth", block: "start" });
    });
    rows.push([row, i]);
  }

  function select(i) {
    if (!(i >= 0 && i < N)) return;
    state.current = i;
    if (i > 0 && i !== state.errorOf) {
      state.errorOf = i;
      computeError();
      paintError();
    }
    paintShown();
    updateLabels();
    updateReadout();
    draw();
  }

  function updateLabels() {
    const i = state.current;
    viewer.dataset.current = String(i);
    viewer.dataset.label = images[i].label;
    viewer.dataset.error = state.showError ? "on" : "off";
    $("image-label").textContent = images[i].label;
    $("image-note").textContent = i === 0 ? "reference" : "estimator " + i + " of " + (N - 1);
    $("error-label").textContent = N > 1
      ? METRIC_NAMES[state.metric] + " of " + images[state.errorOf].label + " against " + images[0].label
      : "no estimator to compare";
    buttons.forEach((b, k) => {
      b.setAttribute("aria-pressed", String(k === i));
      b.classList.toggle("error-target", N > 1 && k === state.errorOf && state.showError);
    });
    for (const [row, k] of rows) row.classList.toggle("current", k === i);
  }

  function setExposure(ev) {
    state.exposure = Math.max(-10, Math.min(10, Math.round(ev * 4) / 4));
    $("exposure").value = String(state.exposure);
    $("exposure-value").textContent = (state.exposure >= 0 ? "+" : "−") + Math.abs(state.exposure).toFixed(2) + " EV";
    paintShown();
    updateReadout();
    draw();
  }

  function setShowError(on) {
    state.showError = on && N > 1;
    $("show-error").checked = state.showError;
    viewer.dataset.error = state.showError ? "on" : "off";
    resizeCanvases();
    updateLabels();
    updateReadout();
    draw();
  }

  function setMetric(m) {
    state.metric = m;
    $("metric").value = m;
    computeError();
    paintError();
    updateLabels();
    updateReadout();
    draw();
  }

  buttons.forEach((b, i) => b.addEventListener("click", () => select(i)));
  $("exposure").addEventListener("input", (e) => setExposure(+e.target.value));
  $("zoom-in").addEventListener("click", () => zoomCentre(1));
  $("zoom-out").addEventListener("click", () => zoomCentre(-1));
  $("fit").addEventListener("click", () => { fit(); draw(); });
  $("show-error").addEventListener("change", (e) => setShowError(e.target.checked));
  $("metric").addEventListener("change", (e) => setMetric(e.target.value));
  const rangeSelect = $("range");
  RANGES.forEach((r, i) => rangeSelect.add(new Option(rangeName(r), String(i))));
  rangeSelect.addEventListener("change", (e) => {
    state.range = +e.target.value;
    paintError();
    updateReadout();
    draw();
  });

  document.addEventListener("keydown", (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey) return;     // leave browser shortcuts alone
    const t = e.target;
    const tag = t && t.tagName;
    if (tag === "SELECT" || tag === "TEXTAREA" || (tag === "INPUT" && t.type !== "range" && t.type !== "checkbox")) return;
    if (tag === "INPUT" && t.type === "range" && e.key.startsWith("Arrow")) return;
    const k = e.key;
    if (/^[0-9]$/.test(k)) {
      select(k === "0" ? 9 : +k - 1);                // 1 = the reference, 2.. = estimators
    } else {
      switch (k) {
        case "ArrowRight": case "]": select((state.current + 1) % N); break;
        case "ArrowLeft": case "[": select((state.current + N - 1) % N); break;
        case "+": case "=": zoomCentre(1); break;
        case "-": case "_": zoomCentre(-1); break;
        case "f": case "F": fit(); draw(); break;
        case "e": setExposure(state.exposure + 0.5); break;
        case "E": setExposure(state.exposure - 0.5); break;
        case "r": case "R": setExposure(0); break;
        case "x": case "X": setShowError(!state.showError); break;
        case "m": case "M": setMetric(state.metric === "smape" ? "relative" : "smape"); break;
        default: return;
      }
    }
    e.preventDefault();
  });

  new ResizeObserver(() => {
    resizeCanvases();
    draw();
  }).observe(views[0].canvas);

  // ---- Start ---------------------------------------------------------------------------
  viewer.dataset.error = state.showError ? "on" : "off";
  const ready = Promise.all(images.map((im) => decodeImage(im.png))).then((values) => {
    values.forEach((d, i) => { linear[i] = d; });
    decoded = true;
    if (N > 1) computeError();
    paintError();
    paintShown();
    resizeCanvases();
    updateLabels();
    updateReadout();
    draw();
    viewer.dataset.ready = "true";
  }).catch((err) => {
    viewer.dataset.ready = "error";
    $("loading").textContent = "Could not decode the images: " + err.message;
    throw err;
  });

  // For scripts and tests: the state, and the decoded values.
  window.fogViewer = {
    state, ready, select, width: W, height: H, count: N,
    pixel: (i, x, y) => Array.from(linear[i].subarray(3 * (y * W + x), 3 * (y * W + x) + 3)),
    error: (x, y) => errorValues[y * W + x],
  };
})();
