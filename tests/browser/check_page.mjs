// Checks a comparison page (index.html, written by `fogplanes table`) in a real browser:
// headless Chromium via playwright-core. `check.sh` beside it renders a small table and runs this.
//
//   node check_page.mjs path/to/index.html [--shots DIR]
//
// Screenshots go to DIR (default: beside the page). Chromium is /usr/bin/chromium, or $CHROMIUM.
//
// Loads the page from a file:// URL with every outside load refused, and checks that: the
// images decode (and, when an expected.json lies beside the page, to its values: {"pixels":
// [{x, y, original, decoded, smape1}]}, one [r, g, b] per image; `fogplanes table` writes
// none); the screenshot is not blank; a number key changes the shown image (data attribute,
// label text, canvas pixels), also when pressed (or a button clicked) while the images still
// decode; zoom is pixel-exact and the two views pan together; exposure, the
// error view toggle and table rows work; and nothing is fetched and nothing is logged as an
// error. Exits 1 on any failure.

import { chromium } from "playwright-core";
import { existsSync, mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { dirname, resolve } from "node:path";
import { pathToFileURL } from "node:url";

const args = process.argv.slice(2);
const shotsAt = args.indexOf("--shots");
const shots = shotsAt >= 0 ? resolve(args.splice(shotsAt, 2)[1]) : null;
if (!args[0]) {
  console.error("usage: node check_page.mjs path/to/index.html [--shots DIR]");
  process.exit(2);
}
const pagePath = resolve(args[0]);
const shotDir = shots || dirname(pagePath);
mkdirSync(shotDir, { recursive: true });

const failures = [];
let passed = 0;
function check(ok, what) {
  if (ok) {
    passed++;
    console.log("ok    " + what);
  } else {
    failures.push(what);
    console.log("FAIL  " + what);
  }
}

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
  ],
});

try {
  const context = await browser.newContext({ viewport: { width: 1440, height: 980 }, deviceScaleFactor: 1 });
  const page = await context.newPage();
  const outside = [];
  const problems = [];
  page.on("request", (r) => {
    const u = r.url();
    if (!u.startsWith("file:") && !u.startsWith("data:") && !u.startsWith("blob:")) outside.push(u);
  });
  await context.route("**/*", (route) => {
    const u = route.request().url();
    if (u.startsWith("file:") || u.startsWith("data:") || u.startsWith("blob:")) return route.continue();
    outside.push(u);
    return route.abort();
  });
  page.on("console", (m) => {
    // Chromium's hint about repeated getImageData comes from this script's own readbacks.
    if (m.type() === "warning" && m.text().includes("willReadFrequently")) return;
    if (m.type() === "error" || m.type() === "warning") problems.push(m.type() + ": " + m.text());
  });
  page.on("pageerror", (e) => problems.push("pageerror: " + e.message));

  const t0 = Date.now();
  await page.goto(pathToFileURL(pagePath).href);
  await page.waitForSelector('#viewer[data-ready="true"], #viewer[data-ready="error"]', { timeout: 60000 });
  const readyState = await page.getAttribute("#viewer", "data-ready");
  check(readyState === "true", `images decoded (data-ready=${readyState}, ${Date.now() - t0} ms)`);
  const info = await page.evaluate(() => ({ n: fogViewer.count, w: fogViewer.width, h: fogViewer.height }));
  console.log(`      ${info.n} images of ${info.w}x${info.h}`);

  // ---- Decoded values against the writer's own decoding ------------------------------------
  const expectedPath = resolve(dirname(pagePath), "expected.json");
  if (existsSync(expectedPath)) {
    const expected = JSON.parse(readFileSync(expectedPath, "utf8"));
    const got = await page.evaluate((pts) => pts.map((p) => ({
      values: Array.from({ length: fogViewer.count }, (_, i) => fogViewer.pixel(i, p.x, p.y)),
      error: fogViewer.error(p.x, p.y),
    })), expected.pixels);
    let exact = 0, total = 0, worstRgbe = 0, worstError = 0;
    expected.pixels.forEach((p, k) => {
      p.decoded.forEach((d, i) => {
        for (let c = 0; c < 3; c++) {
          total++;
          if (Math.fround(d[c]) === got[k].values[i][c]) exact++;
          const o = Math.max(0, p.original[i][c]);
          const m = Math.max(...p.original[i].map((v) => Math.max(0, v)));
          if (m > 0) worstRgbe = Math.max(worstRgbe, Math.abs(got[k].values[i][c] - o) / m);
        }
      });
      worstError = Math.max(worstError, Math.abs(got[k].error - p.smape1) / Math.max(1e-12, Math.abs(p.smape1)));
    });
    check(exact === total, `decoded values equal the Rust decoding bit for bit (${exact}/${total})`);
    check(worstRgbe <= 1 / 256 + 1e-6, `decoded values within 1/256 of the brightest channel (worst ${worstRgbe.toExponential(2)})`);
    check(worstError < 1e-6, `per-pixel SMAPE of estimator 1 matches (worst relative difference ${worstError.toExponential(2)})`);
  } else {
    console.log("      (no expected.json beside the page: value check skipped)");
  }

  // ---- Helpers -------------------------------------------------------------------------
  const canvasHash = (sel, p = page) => p.evaluate((sel) => {
    const c = document.querySelector(sel);
    const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    let h = 2166136261;
    for (let i = 0; i < d.length; i += 1) h = Math.imul(h ^ d[i], 16777619);
    return (h >>> 0).toString(16) + ":" + c.width + "x" + c.height;
  }, sel);
  const IMG = "#image-view canvas.view-canvas", ERR = "#error-view canvas.view-canvas";
  const state = () => page.evaluate(() => ({ ...fogViewer.state }));

  // Distinct colours of a PNG, counted in a blank page (the checked page's CSP is strict).
  const scratch = await context.newPage();
  const distinctColours = (png) => scratch.evaluate(async (b64) => {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const bmp = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
    const c = new OffscreenCanvas(bmp.width, bmp.height);
    const ctx = c.getContext("2d");
    ctx.drawImage(bmp, 0, 0);
    const d = ctx.getImageData(0, 0, bmp.width, bmp.height).data;
    const set = new Set();
    for (let i = 0; i < d.length; i += 4) set.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
    return set.size;
  }, png.toString("base64"));

  // ---- The first view ------------------------------------------------------------------
  await page.mouse.move(2, 2);
  const shot = await page.screenshot({ path: resolve(shotDir, "screenshot.png") });
  await page.screenshot({ path: resolve(shotDir, "screenshot-full.png"), fullPage: true });
  const colours = await distinctColours(shot);
  check(colours > 2000, `screenshot is not blank (${colours} distinct colours)`);
  const viewShot = await page.locator(IMG).screenshot();
  const viewColours = await distinctColours(viewShot);
  check(viewColours > 500, `the image view shows an image (${viewColours} distinct colours)`);
  const errColours = await distinctColours(await page.locator(ERR).screenshot());
  check(errColours > 50, `the error view shows a false-colour map (${errColours} distinct colours)`);

  // ---- Flip with a number key -----------------------------------------------------------
  const labels = await page.$$eval(".choices button span", (s) => s.map((x) => x.textContent));
  const before = { current: await page.getAttribute("#viewer", "data-current"), label: await page.textContent("#image-label"), hash: await canvasHash(IMG) };
  check(before.current === "0" && before.label === labels[0], `starts on the reference (${before.label})`);
  await page.keyboard.press("3");
  const after = { current: await page.getAttribute("#viewer", "data-current"), label: await page.textContent("#image-label"), hash: await canvasHash(IMG) };
  check(after.current === "2", `key 3 selects image 2 (data-current=${after.current})`);
  check(after.label === labels[2], `the label follows (${after.label})`);
  check(after.hash !== before.hash, "the image view's pixels change");
  check(await page.getAttribute('.choices button[data-index="2"]', "aria-pressed") === "true", "its button is pressed");
  check((await page.textContent("#error-label")).includes(labels[2]), "the error view follows the chosen estimator");
  await page.keyboard.press("1");
  check(await canvasHash(IMG) === before.hash && (await page.getAttribute("#viewer", "data-current")) === "0", "key 1 brings back the reference, pixel for pixel");
  await page.click('.choices button[data-index="4"]');
  check(await page.getAttribute("#viewer", "data-current") === "4", "a button click selects its image");
  await page.keyboard.press("ArrowRight");
  check(await page.getAttribute("#viewer", "data-current") === String(5 % labels.length), "the right arrow selects the next image");

  // ---- Zoom: pixel-exact integer magnification, views in step --------------------------
  await page.keyboard.press("2");
  const fitZoom = (await state()).zoom;
  for (let i = 0; i < 3; i++) await page.keyboard.press("+");
  const z = (await state()).zoom;
  check(z > fitZoom && Number.isInteger(z), `+ zooms in to an integer level (${fitZoom} -> ${z})`);
  const runs = await page.evaluate((sel) => {
    const c = document.querySelector(sel);
    const y = Math.floor(c.height / 2);
    const d = c.getContext("2d").getImageData(0, y, c.width, 1).data;
    const lengths = [];
    let n = 1;
    for (let x = 1; x < c.width; x++) {
      const same = d[4 * x] === d[4 * x - 4] && d[4 * x + 1] === d[4 * x - 3] && d[4 * x + 2] === d[4 * x - 2];
      if (same) n++; else { lengths.push(n); n = 1; }
    }
    lengths.push(n);
    return lengths.slice(1, -1);   // the end runs may be cut by the canvas edge
  }, IMG);
  check(runs.length > 10 && runs.every((r) => r % z === 0), `magnified pixels are exact ${z}x${z} blocks (${runs.length} runs, lengths ${[...new Set(runs)].join(",")})`);
  const imgBox = await page.locator(IMG).boundingBox();
  const errBox = await page.locator(ERR).boundingBox();
  await page.mouse.move(imgBox.x + imgBox.width / 2, imgBox.y + imgBox.height / 2);
  await page.mouse.wheel(0, -100);
  await page.waitForTimeout(50);
  const z2 = (await state()).zoom;
  check(z2 > z, `the wheel zooms in (${z} -> ${z2})`);
  const s0 = await state();
  await page.mouse.down();
  await page.mouse.move(imgBox.x + imgBox.width / 2 + 120, imgBox.y + imgBox.height / 2 + 40, { steps: 5 });
  await page.mouse.up();
  const s1 = await state();
  check(Math.abs((s0.cx - s1.cx) * s1.zoom - 120) < 1 && Math.abs((s0.cy - s1.cy) * s1.zoom - 40) < 1, `dragging pans (centre ${s0.cx.toFixed(1)},${s0.cy.toFixed(1)} -> ${s1.cx.toFixed(1)},${s1.cy.toFixed(1)})`);
  // The same spot in both views reads out the same pixel.
  const at = [0.3, 0.6];
  await page.mouse.move(imgBox.x + imgBox.width * at[0], imgBox.y + imgBox.height * at[1]);
  const hoverImg = (await state()).hover;
  await page.mouse.move(errBox.x + errBox.width * at[0], errBox.y + errBox.height * at[1]);
  const hoverErr = (await state()).hover;
  check(hoverImg && hoverErr && hoverImg[0] === hoverErr[0] && hoverImg[1] === hoverErr[1], `the views are in step (pixel ${hoverImg} in both)`);
  const readout = await page.textContent("#readout");
  check(readout.includes(`x ${hoverErr[0]}  y ${hoverErr[1]}`) && readout.includes(labels[0]) && readout.includes(labels[1]), "the readout names the pixel, the shown image and the reference");
  await page.screenshot({ path: resolve(shotDir, "screenshot-zoom.png") });
  await page.keyboard.press("f");
  check((await state()).zoom === fitZoom, "F fits again");

  // ---- Exposure, error view, metric, table -------------------------------------------------
  await page.mouse.move(2, 2);
  const h0 = await canvasHash(IMG);
  await page.keyboard.press("e");
  check((await state()).exposure === 0.5 && (await canvasHash(IMG)) !== h0, "E raises the exposure by half a stop and the image changes");
  await page.keyboard.press("r");
  check((await state()).exposure === 0 && (await canvasHash(IMG)) === h0, "R resets the exposure");
  const e0 = await canvasHash(ERR);
  await page.keyboard.press("m");
  check((await state()).metric === "relative" && (await canvasHash(ERR)) !== e0, "M switches the error metric");
  await page.keyboard.press("m");
  await page.keyboard.press("x");
  check(await page.getAttribute("#viewer", "data-error") === "off" && !(await page.isVisible("#error-view")), "X hides the error view");
  await page.keyboard.press("x");
  check(await page.isVisible("#error-view"), "X shows it again");
  const rowCount = await page.$$eval("#results tr.selectable", (r) => r.length);
  check(rowCount === labels.length - 1, `every estimator's table row is selectable (${rowCount})`);
  await page.click("#results tr.selectable >> nth=2");
  check(await page.getAttribute("#viewer", "data-current") === "3", "clicking a table row selects its estimator");
  if (await page.$("#plot")) {
    const plot = await page.$$eval("#plot img", (imgs) => imgs.length === 1 && {
      svg: imgs[0].src.startsWith("data:image/svg+xml;base64,"), w: imgs[0].naturalWidth, h: imgs[0].naturalHeight, shown: imgs[0].width,
    });
    check(plot && plot.svg && plot.w > 0 && plot.h > 0 && plot.shown > 0, `the plot is an SVG image inside the page (${plot ? `${plot.w}x${plot.h}, shown ${plot.shown} wide` : "no single #plot img"})`);
    await page.locator("#plot").screenshot({ path: resolve(shotDir, "screenshot-plot.png") });
  } else {
    console.log("      (no plot: a table without a sweep)");
  }

  // ---- Input while the images decode ---------------------------------------------------------
  // Decoding is held back (createImageBitmap waits for a gate the check opens), so these keys and
  // clicks surely come before the images are ready; they must take effect once they are.
  const gated = async () => {
    const p = await context.newPage();
    p.on("pageerror", (e) => problems.push("pageerror (while decoding): " + e.message));
    await p.addInitScript(() => {
      const decode = window.createImageBitmap.bind(window);
      let open;
      const gate = new Promise((resolve) => { open = resolve; });
      window.openDecodeGate = open;
      window.createImageBitmap = (...a) => gate.then(() => decode(...a));
    });
    await p.goto(pathToFileURL(pagePath).href);
    return p;
  };
  const openGate = async (p) => {
    await p.evaluate(() => window.openDecodeGate());
    await p.waitForSelector('#viewer[data-ready="true"], #viewer[data-ready="error"]', { timeout: 60000 });
    await p.mouse.move(2, 2);
  };
  const early = await gated();
  check(await early.getAttribute("#viewer", "data-ready") === "false", "decoding held back: the page is not ready yet");
  await early.keyboard.press("3");
  await openGate(early);
  const kept = { current: await early.getAttribute("#viewer", "data-current"), label: await early.textContent("#image-label"), hash: await canvasHash(IMG, early) };
  check(kept.current === "2" && kept.label === labels[2], `key 3 pressed while decoding selects image 2 once ready (data-current=${kept.current}, ${kept.label})`);
  check((await early.textContent("#error-label")).includes(labels[2]), "the error view follows it");
  await early.keyboard.press("1");
  await early.keyboard.press("3");
  check(kept.hash === await canvasHash(IMG, early), "and shows its pixels, as key 3 pressed after decoding does");
  await early.close();
  const clicked = await gated();
  await clicked.click('.choices button[data-index="4"]');
  await clicked.keyboard.press("e");
  await clicked.keyboard.press("m");
  check(await clicked.getAttribute("#viewer", "data-ready") === "false", "still decoding after a click and two keys");
  await openGate(clicked);
  const s = await clicked.evaluate(() => ({ ...fogViewer.state }));
  check(await clicked.getAttribute("#viewer", "data-current") === "4" && s.errorOf === 4, `a button clicked while decoding selects its image once ready (data-current=${s.current})`);
  check(s.exposure === 0.5 && s.metric === "relative", `exposure and metric keys pressed while decoding are kept (${s.exposure} EV, ${s.metric})`);
  await clicked.close();

  check(outside.length === 0, `nothing is fetched from outside (${outside.length}${outside.length ? ": " + outside.slice(0, 3).join(", ") : ""})`);
  check(problems.length === 0, `no console errors or warnings${problems.length ? ": " + problems.join(" | ") : ""}`);
} catch (e) {
  failures.push("exception: " + (e && e.stack || e));
  console.log("FAIL  " + (e && e.stack || e));
} finally {
  await browser.close();
}

console.log(`\n${passed} passed, ${failures.length} failed`);
process.exit(failures.length ? 1 : 0);
