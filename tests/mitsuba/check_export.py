#!/usr/bin/env python3
"""Checks `fogplanes export --format mitsuba` against fogplanes' own reference renderer.

Exports SCENE with the fogplanes binary, renders the XML with Mitsuba 3 (scalar_rgb variant) in
several passes of different seeds (no two sharing a random stream), renders fogplanes' jittered
reference with its per-pixel standard error, and compares the two block by block: for each
block of BLOCK x BLOCK pixels and each channel, z = (Mitsuba's block mean - the reference's) /
the combined standard error. The reference's standard error comes from its --stderr-image;
Mitsuba's from the spread of each pixel over the passes, pooled over the block's pixels (pixels
are independent: the box filter keeps every sample in its own pixel, and no stream is shared).

Exit status: 0 when every block lies within --max-block-z standard errors and every channel's
image mean within --max-mean-z; 1 when not (or when the image looks mirrored); 2 on bad usage
or when a tool fails.

    python3 tests/mitsuba/check_export.py media_scenes/six_lights.toml target/release/fogplanes \\
        --resolution 64x36 --spp 2048 --passes 8 --ref-spp 4096
"""

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time


def parse_resolution(text):
    try:
        w, h = text.lower().split("x")
        w, h = int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}")
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f"both sides must be positive, got {text!r}")
    return w, h


def positive_int(text):
    v = int(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text!r}")
    return v


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", help="the scene file (TOML)")
    p.add_argument("fogplanes", help="path of the fogplanes binary")
    p.add_argument("--resolution", type=parse_resolution, default=(64, 36), metavar="WxH")
    p.add_argument("--spp", type=positive_int, default=2048, help="Mitsuba samples per pixel in all (default 2048)")
    p.add_argument("--passes", type=positive_int, default=8, help="Mitsuba passes (seeds) the spp is split into")
    p.add_argument("--ref-spp", type=positive_int, default=4096, help="reference samples per pixel (default 4096)")
    p.add_argument("--seed", type=int, default=1, help="first seed of both renderers")
    p.add_argument("--block", type=positive_int, default=8, help="block side in pixels (default 8)")
    p.add_argument("--max-block-z", type=float, default=5.0)
    p.add_argument("--max-mean-z", type=float, default=4.0)
    p.add_argument("--workdir", help="keep the files here (default: a temporary directory)")
    a = p.parse_args()
    if a.passes < 2:
        p.error("--passes must be at least 2 (Mitsuba's error comes from their spread)")
    if a.spp % a.passes:
        p.error(f"--spp {a.spp} must be a multiple of --passes {a.passes}")

    try:
        import numpy as np
        import mitsuba as mi
    except ImportError as e:
        print(f"error: {e} (pip install mitsuba numpy)", file=sys.stderr)
        return 2
    mi.set_variant("scalar_rgb")

    if a.workdir:
        os.makedirs(a.workdir, exist_ok=True)
        return run(a, np, mi, a.workdir)
    with tempfile.TemporaryDirectory(prefix="fogplanes-mitsuba-") as work:
        return run(a, np, mi, work)


def fogplanes(a, *args):
    cmd = [a.fogplanes, *args]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {r.returncode}:\n{r.stderr.strip()}")
    return r.stdout


def run(a, np, mi, work):
    w, h = a.resolution
    xml = os.path.join(work, "scene.xml")
    ref, err, mit = (os.path.join(work, n) for n in ("reference.exr", "reference_stderr.exr", "mitsuba.exr"))
    try:
        fogplanes(a, "export", a.scene, "--format", "mitsuba", "-o", xml)
        t0 = time.perf_counter()
        fogplanes(a, "reference", a.scene, "--resolution", f"{w}x{h}", "--spp", str(a.ref_spp),
                  "--seed", str(a.seed), "-o", ref, "--stderr-image", err, "--quiet")
        ref_seconds = time.perf_counter() - t0
    except (RuntimeError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    # Mitsuba: one load, then passes with seeds seed, seed + stride, ... Mitsuba seeds pixel i of
    # block b with seed * w * h + b * B^2 + i, its blocks (B <= 32 pixels wide) covering the
    # film: consecutive seeds would share random streams between pixels of two passes, which
    # their spread would not show.
    t0 = time.perf_counter()
    per_pass = a.spp // a.passes
    scene = mi.load_file(xml, resx=w, resy=h, spp=per_pass)
    stride = -(-(w + 32) * (h + 32) // (w * h))
    passes = []
    for k in range(a.passes):
        img = mi.render(scene, seed=a.seed + k * stride, spp=per_pass)
        passes.append(np.array(img, dtype=np.float64)[..., :3])
    mi_seconds = time.perf_counter() - t0
    passes = np.stack(passes)  # (passes, h, w, 3)
    mi_mean = passes.mean(axis=0)
    # Variance of each pixel's mean over passes, per channel and for the channel average.
    mi_var = passes.var(axis=0, ddof=1) / a.passes
    mi_var_grey = passes.mean(axis=3).var(axis=0, ddof=1) / a.passes
    mi.Bitmap(mi_mean.astype(np.float32)).write(mit)

    ref_mean = np.array(mi.Bitmap(ref), dtype=np.float64)[..., :3]
    ref_se = np.array(mi.Bitmap(err), dtype=np.float64)[..., :3]
    if ref_mean.shape != mi_mean.shape:
        print(f"error: the reference is {ref_mean.shape} but Mitsuba rendered {mi_mean.shape}", file=sys.stderr)
        return 2
    ref_var = ref_se**2

    # Blocks (the last row and column of blocks may be partial).
    b = a.block
    rows, cols = range(0, h, b), range(0, w, b)
    z = np.zeros((len(rows), len(cols), 3))
    # A block where Mitsuba saw no light at all in most passes while the reference sees a faint
    # glow (below 1e-3 of the image mean) has no usable Mitsuba error estimate: in a near
    # vacuum hardly any of its paths scatter. Such blocks are shown but not judged.
    rare = np.zeros(z.shape, dtype=bool)
    faint = 1e-3 * ref_mean.mean(axis=(0, 1))
    for i, y0 in enumerate(rows):
        for j, x0 in enumerate(cols):
            sl = (slice(y0, y0 + b), slice(x0, x0 + b))
            n = mi_mean[sl].shape[0] * mi_mean[sl].shape[1]
            ref_block = ref_mean[sl].mean(axis=(0, 1))
            diff = mi_mean[sl].mean(axis=(0, 1)) - ref_block
            se = np.sqrt((mi_var[sl].sum(axis=(0, 1)) + ref_var[sl].sum(axis=(0, 1))) / n**2)
            z[i, j] = np.where(se > 0, diff / np.where(se > 0, se, 1), np.where(diff == 0, 0.0, np.inf))
            dark_passes = (passes[:, sl[0], sl[1]].sum(axis=(1, 2)) == 0).sum(axis=0)
            rare[i, j] = (2 * dark_passes >= a.passes) & (ref_block < faint)

    npix = w * h
    print(f"scene {a.scene} at {w}x{h}; Mitsuba {a.spp} spp in {a.passes} passes, {mi_seconds:.1f} s; "
          f"fogplanes reference {a.ref_spp} spp, {ref_seconds:.1f} s")
    print()
    print(f"block z-scores ({b}x{b} pixels), largest |z| over R, G, B, signed:")
    print("      " + "".join(f"{x0:>7}" for x0 in cols))
    for i, y0 in enumerate(rows):
        cells = []
        for j in range(len(cols)):
            judged = np.where(rare[i, j], 0.0, np.abs(z[i, j]))
            k = int(np.argmax(judged))
            cells.append("   rare" if rare[i, j].all() else f"{z[i, j, k]:>7.2f}")
        print(f"{y0:>6}" + "".join(cells))
    if rare.any():
        print(f"rare: {rare.sum()} block-channels where Mitsuba saw no light in most passes and the "
              "reference a faint glow; not judged")
    flat = np.abs(z[~rare]).ravel()
    finite = flat[np.isfinite(flat)]
    rms = math.sqrt(float((finite**2).mean())) if finite.size else float("nan")
    print(f"{flat.size} block-channel z-scores: max |z| {flat.max(initial=0):.2f}, RMS {rms:.2f} (1 expected), "
          f"|z| > 2: {(flat > 2).sum()} ({100 * (flat > 2).mean():.1f}%, 4.6% expected), "
          f"|z| > 3: {(flat > 3).sum()} (0.27% expected)")
    print()

    # Image means: per channel exact; for the channel average the reference's channels are
    # taken as fully correlated (an upper bound of its standard error).
    print(f"{'image mean':<12}{'Mitsuba':>22}{'fogplanes reference':>26}{'ratio':>9}{'z':>8}")
    ok = True
    labels = ["R", "G", "B", "RGB"]
    for c, label in enumerate(labels):
        if c < 3:
            m, r = mi_mean[..., c].mean(), ref_mean[..., c].mean()
            mse, rse = math.sqrt(mi_var[..., c].sum()) / npix, math.sqrt(ref_var[..., c].sum()) / npix
        else:
            m, r = mi_mean.mean(), ref_mean.mean()
            mse = math.sqrt(mi_var_grey.sum()) / npix
            rse = math.sqrt((ref_se.mean(axis=2) ** 2).sum()) / npix
        se = math.hypot(mse, rse)
        zm = (m - r) / se if se > 0 else (0.0 if m == r else math.inf)
        ratio = m / r if r != 0 else math.nan
        print(f"{label:<12}{m:>12.6f} +- {mse:.1e}{r:>16.6f} +- {rse:.1e}{ratio:>9.4f}{zm:>8.2f}")
        if abs(zm) > a.max_mean_z:
            ok = False
            print(f"FAIL: the {label} image mean differs by {zm:.2f} standard errors (limit {a.max_mean_z})")

    # Orientation: a mirrored export would match clearly better mirrored back. (In a scene
    # symmetric about an axis the two are equal within noise, and that axis proves nothing.)
    direct = np.abs(mi_mean - ref_mean).mean()
    mirrored_x = np.abs(mi_mean[:, ::-1] - ref_mean).mean()
    mirrored_y = np.abs(mi_mean[::-1] - ref_mean).mean()
    print()
    print(f"mean |Mitsuba - reference|: {direct:.4g} as is, {mirrored_x:.4g} mirrored left-right, "
          f"{mirrored_y:.4g} mirrored top-bottom")
    for name, mirrored in [("left-right", mirrored_x), ("top-bottom", mirrored_y)]:
        if mirrored < 0.8 * direct:
            ok = False
            print(f"FAIL: the Mitsuba image matches better mirrored {name}: the export's orientation is wrong")
        elif mirrored < 1.25 * direct:
            print(f"note: the scene looks symmetric {name}; that orientation is not checked")

    worst = flat.max() if flat.size else 0.0
    if worst > a.max_block_z:
        ok = False
        bad = np.argwhere((np.abs(z) > a.max_block_z) & ~rare)
        for i, j, c in bad[:10]:
            print(f"FAIL: block at x={cols[j]} y={rows[i]} channel {'RGB'[c]}: z = {z[i, j, c]:.2f}")
        if len(bad) > 10:
            print(f"... and {len(bad) - 10} more blocks beyond {a.max_block_z} standard errors")
    print()
    print("agreement: OK" if ok else "agreement: FAILED")
    if a.workdir:
        print(f"files in {a.workdir}: scene.xml, reference.exr, reference_stderr.exr, mitsuba.exr")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
