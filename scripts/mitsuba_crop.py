#!/usr/bin/env python3
"""Per-pixel comparison of a crop of fogplanes' renders with Mitsuba 3 (docs/mitsuba_red_spot.md).

    # Mitsuba: the exported scene, a crop, independent batches of different seeds
    fogplanes export media_scenes/six_lights.toml --format mitsuba -o six_lights.xml
    scripts/mitsuba_crop.py mitsuba six_lights.xml mi.npy --crop 482,118,26,24 --spp 8192 --batches 32
    #   ... with the camera moved back by Mitsuba's ray offset at the box's front face:
    scripts/mitsuba_crop.py mitsuba six_lights.xml mi_moved.npy --camera-shift 0,0,5.364418029785156e-4
    # fogplanes: renders of different seeds (whole images), cropped
    scripts/mitsuba_crop.py fogplanes fp.npy fp_s1.exr fp_s2.exr ... --crop 482,118,26,24
    scripts/mitsuba_crop.py compare mi.npy fp.npy

Each .npy holds a stack (batches or seeds, height, width, 3) of independent estimates of the
crop; means and standard errors come from their spread. `compare` prints, over the crop and
over the pixels the red spot covers (the two means' average R above 1; the glow around it stays below
0.6): the per-pixel excess, mean of (fogplanes - Mitsuba)^2 minus both variances, against that
noise; the z-scores; the crop's sum with a standard error from the spread of the sums (a
photon plane reaches many pixels, so fogplanes' pixels are correlated); and the z-scores
between Mitsuba's two halves of batches, which test its own noise estimate. Mitsuba's variant
is scalar_rgb, as in tests/mitsuba/check_export.py.
"""

import argparse
import sys
import time


def crop_arg(text):
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,WIDTH,HEIGHT, got {text!r}")
    if min(x, y) < 0 or min(w, h) <= 0:
        raise argparse.ArgumentTypeError(f"offsets must be >= 0 and sizes > 0, got {text!r}")
    return x, y, w, h


def vector_arg(text):
    try:
        v = [float(t) for t in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3:
        raise argparse.ArgumentTypeError(f"expected DX,DY,DZ, got {text!r}")
    return v


def seed_stride(w, h):
    """How far apart the seeds of independent renders of a w x h film must be. Mitsuba 3 (CPU)
    seeds pixel i of block b with seed * w * h + b * B^2 + i, its blocks B = 32 pixels (or fewer)
    wide covering the film, so that consecutive seeds reuse random streams (in other pixels)
    unless w and h are multiples of B (src/render/integrator.cpp, render and render_block)."""
    return -(-(w + 32) * (h + 32) // (w * h))


def mitsuba(a, np):
    import mitsuba as mi
    import re
    mi.set_variant("scalar_rgb")
    x, y, w, h = a.crop
    text = open(a.xml).read()
    text = text.replace('<rfilter type="box"/>', '<rfilter type="box"/>\n'
                        f'            <integer name="crop_offset_x" value="{x}"/>\n'
                        f'            <integer name="crop_offset_y" value="{y}"/>\n'
                        f'            <integer name="crop_width" value="{w}"/>\n'
                        f'            <integer name="crop_height" value="{h}"/>')
    if a.max_depth is not None:
        text, n = re.subn(r'(<integer name="max_depth" value=")\d+', rf"\g<1>{a.max_depth}", text)
        assert n == 1, "the integrator has no max_depth"
    if a.hide_emitters:
        text = text.replace('name="hide_emitters" value="false"', 'name="hide_emitters" value="true"')
    if any(a.camera_shift):
        def moved(m):
            p = [float(v) + d for v, d in zip(m.group(2).split(","), a.camera_shift)]
            return f'{m.group(1)}="{p[0]!r}, {p[1]!r}, {p[2]!r}"'
        text, n = re.subn(r'(origin|target)="([^"]*)"', moved, text)
        assert n == 2, "the sensor's lookat has no origin and target"
    scene = mi.load_string(text)
    out, t0 = [], time.perf_counter()
    for b in range(a.batches):
        img = mi.render(scene, seed=a.seed + b * seed_stride(w, h), spp=a.spp)
        out.append(np.array(img, dtype=np.float64)[..., :3])
        print(f"batch {b + 1}/{a.batches}, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    np.save(a.out, np.stack(out))


def fogplanes(a, np):
    import mitsuba as mi  # only to read EXR
    mi.set_variant("scalar_rgb")
    x, y, w, h = a.crop
    stack = [np.array(mi.Bitmap(p), dtype=np.float64)[y:y + h, x:x + w, :3] for p in a.images]
    np.save(a.out, np.stack(stack))


def compare(a, np):
    mi, fp = np.load(a.mitsuba), np.load(a.fogplanes)
    if mi.shape[1:] != fp.shape[1:]:
        sys.exit(f"error: the crops differ: {mi.shape[1:]} and {fp.shape[1:]}")
    nb, nf = len(mi), len(fp)
    m, f = mi.mean(0), fp.mean(0)
    var_m = mi.var(0, ddof=1) / nb
    var_f = fp.var(0, ddof=1) / nf if nf > 1 else np.zeros_like(f)
    d, var = f - m, var_m + var_f
    spot = (m + f)[..., 0] > 2.0  # both means' average above 1: the panel's pixels
    print(f"Mitsuba: {nb} batches; fogplanes: {nf} seeds; crop {m.shape[1]}x{m.shape[0]} pixels, "
          f"{spot.sum()} of them in the spot")
    for name, sel in [("crop", np.ones_like(spot)), ("spot", spot)]:
        ok = sel[..., None] & (var > 0)
        z = d[ok] / np.sqrt(var[ok])
        excess = (d**2 - var)[ok].mean()
        print(f"{name}: per pixel and channel, excess {excess:.2e} over noise {var[ok].mean():.2e} "
              f"({100 * excess / var[ok].mean():+.0f}%); z RMS {np.sqrt((z**2).mean()):.2f}, "
              f"max |z| {np.abs(z).max():.1f}, |z| > 3: {(np.abs(z) > 3).sum()} of {z.size}")
    sums_m, sums_f = mi.sum((1, 2)), fp.sum((1, 2))
    for c in range(3):
        se_f = sums_f[:, c].std(ddof=1) / np.sqrt(nf) if nf > 1 else 0.0
        se = np.hypot(sums_m[:, c].std(ddof=1) / np.sqrt(nb), se_f)
        diff = sums_f[:, c].mean() - sums_m[:, c].mean()
        print(f"crop sum {'RGB'[c]}: fogplanes - Mitsuba {diff:+.3f} +- {se:.3f} "
              f"(of {sums_m[:, c].mean():.2f})")
    h1, h2 = mi[: nb // 2], mi[nb // 2:]
    vh = h1.var(0, ddof=1) / len(h1) + h2.var(0, ddof=1) / len(h2)
    zh = (h1.mean(0) - h2.mean(0))[vh > 0] / np.sqrt(vh[vh > 0])
    print(f"Mitsuba's halves against each other: z RMS {np.sqrt((zh**2).mean()):.2f}, "
          f"max |z| {np.abs(zh).max():.1f}")
    print("z of fogplanes - Mitsuba, R, the spot's pixels ('.' outside):")
    zr = np.where(spot, d[..., 0] / np.sqrt(np.where(var[..., 0] > 0, var[..., 0], np.inf)), np.nan)
    for row in zr:
        print(" ".join("   ." if np.isnan(v) else f"{v:+4.0f}" for v in row))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    m = sub.add_parser("mitsuba", help="render a crop of an exported scene in independent batches")
    m.add_argument("xml")
    m.add_argument("out", help="the .npy to write: (batches, height, width, 3)")
    m.add_argument("--crop", type=crop_arg, default=(482, 118, 26, 24), metavar="X,Y,W,H")
    m.add_argument("--spp", type=int, default=8192)
    m.add_argument("--batches", type=int, default=32)
    m.add_argument("--seed", type=int, default=1, help="seed of the first batch; the next ones follow, "
                   "spaced so that no two batches share a random stream")
    m.add_argument("--camera-shift", type=vector_arg, default=[0.0, 0.0, 0.0], metavar="DX,DY,DZ",
                   help="move the camera (lookat origin and target) by this vector")
    m.add_argument("--max-depth", type=int, help="volpath's max_depth instead of the file's 2 (1: the direct "
                   "emission alone)")
    m.add_argument("--hide-emitters", action="store_true", help="leave out the emitters seen directly (the "
                   "scattering alone)")
    f = sub.add_parser("fogplanes", help="crop renders of different seeds into one stack")
    f.add_argument("out")
    f.add_argument("images", nargs="+", help="EXR renders, one per seed")
    f.add_argument("--crop", type=crop_arg, default=(482, 118, 26, 24), metavar="X,Y,W,H")
    c = sub.add_parser("compare", help="per-pixel comparison of two stacks")
    c.add_argument("mitsuba")
    c.add_argument("fogplanes")
    a = p.parse_args()
    if a.command == "mitsuba" and (a.spp <= 0 or a.batches < 2):
        p.error("--spp must be positive and --batches at least 2")
    import numpy as np
    {"mitsuba": mitsuba, "fogplanes": fogplanes, "compare": compare}[a.command](a, np)


if __name__ == "__main__":
    main()
