#!/usr/bin/env python3
"""Checks, without noise, that Mitsuba 3 sees every light's outline where fogplanes does.

Exports SCENE with the fogplanes binary and follows Mitsuba's own camera rays through it: the
sensor's `sample_ray` at film position (x / W, y / H), `ray_intersect`, and, where a ray meets
the fog box's null boundary, `spawn_ray` as the `volpath` integrator does. Along each edge of
each light's projection (fogplanes' camera, docs/mathematics.md section 7, computed here in
f64 from the scene file alone), it finds by bisection across the edge where Mitsuba's ray stops
or starts meeting that light, and reports the distance, in pixels, from the projected edge.

Two Mitsuba scenes are traced:

- the export without its fog box: nothing but the camera and the panels, so any distance is a
  disagreement of the camera (fov axis, aspect, pixel offsets), the panels' placement or the
  precision of the exported numbers. Each must stay within --tol pixels (float32 rounding
  leaves about 1e-4).
- the export as it is: Mitsuba moves a ray that crosses the box's boundary off the surface by
  `(1 + max_i |p_i|) * RayEpsilon` (RayEpsilon = 1500 * 2^-24) along its normal, into the box.
  That shifts the outlines by a few thousandths of a pixel (docs/mitsuba_red_spot.md); each
  distance must match that model, traced in f64, within --tol pixels.

Exit status: 0 when both hold, 1 when not, 2 on bad usage or when a tool fails.

    python3 tests/mitsuba/check_outlines.py media_scenes/six_lights.toml target/release/fogplanes
"""

import argparse
import math
import re
import subprocess
import sys
import tempfile
import tomllib
import xml.etree.ElementTree as ET

RAY_EPSILON = 1500 * 2.0**-24  # Mitsuba 3's math::RayEpsilon<float>


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", help="the scene file (TOML)")
    p.add_argument("fogplanes", help="path of the fogplanes binary")
    p.add_argument("--tol", type=float, default=1e-3, help="largest distance allowed, pixels (default 1e-3)")
    p.add_argument("--step", type=float, default=1.0, help="pixels between points along an edge (default 1)")
    a = p.parse_args()
    try:
        import numpy as np
        import mitsuba as mi
    except ImportError as e:
        print(f"error: {e} (pip install mitsuba numpy)", file=sys.stderr)
        return 2
    mi.set_variant("scalar_rgb")
    try:
        with open(a.scene, "rb") as f:
            scene = tomllib.load(f)
        with tempfile.TemporaryDirectory(prefix="fogplanes-outlines-") as work:
            path = f"{work}/scene.xml"
            r = subprocess.run([a.fogplanes, "export", a.scene, "--format", "mitsuba", "-o", path],
                               capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError(f"fogplanes export exited {r.returncode}: {r.stderr.strip()}")
            with open(path) as f:
                text = f.read()
    except (OSError, RuntimeError, tomllib.TOMLDecodeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return run(a, np, mi, scene, text)


class Camera:
    """fogplanes' pinhole camera (docs/mathematics.md section 7), in f64."""

    def __init__(self, np, c):
        self.np = np
        self.pos = np.array(c["position"], dtype=float)
        f = np.array(c["look_at"], dtype=float) - self.pos
        self.f = f / np.linalg.norm(f)
        r = np.cross(self.f, np.array(c["up"], dtype=float))
        self.r = r / np.linalg.norm(r)
        self.u = np.cross(self.r, self.f)
        self.w, self.h = c["resolution"]
        self.tan = math.tan(math.radians(c["vfov_deg"]) / 2)
        self.aspect = self.w / self.h

    def direction(self, x, y):
        sx = (2 * x / self.w - 1) * self.tan * self.aspect
        sy = (1 - 2 * y / self.h) * self.tan
        return self.f + sx * self.r + sy * self.u

    def project(self, p):
        d = p - self.pos
        cx, cy, cz = d @ self.r, d @ self.u, d @ self.f
        return self.np.array([(cx / (cz * self.tan * self.aspect) + 1) * 0.5 * self.w,
                              (1 - cy / (cz * self.tan)) * 0.5 * self.h])


def run(a, np, mi, scene, text):
    cam = Camera(np, scene["camera"])
    lights = scene["light"]
    root = ET.fromstring(text)
    rects = [s for s in root.iter("shape") if s.get("type") == "rectangle"]
    cube = next(s for s in root.iter("shape") if s.get("type") == "cube")
    m = np.array([float(v) for v in cube.find("transform/matrix").get("value").split()]).reshape(4, 4)
    box_lo, box_hi = m[:3, 3] - np.diag(m)[:3], m[:3, 3] + np.diag(m)[:3]
    inside = bool(np.all(cam.pos > box_lo) and np.all(cam.pos < box_hi))
    with_box = mi.load_string(text)
    # The same file without the box (and without the camera's medium reference, if any).
    bare = re.sub(r'\s*<shape type="cube".*?</shape>', "", text, flags=re.S)
    bare = bare.replace('<ref id="fog" name="medium"/>', "")
    without_box = mi.load_string(bare)
    w, h = cam.w, cam.h

    def mitsuba_sees(mscene, k):
        sensor = mscene.sensors()[0]
        target = rects[k].get("id")

        def sees(x, y):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / w, y / h), mi.Point2f(0.5))
            for _ in range(8):
                si = mscene.ray_intersect(ray)
                if not si.is_valid():
                    return False
                if si.shape.id() != cube.get("id"):
                    return si.shape.id() == target
                ray = si.spawn_ray(si.to_world(-si.wi))  # a null BSDF: volpath's continuation
            return False
        return sees

    def model_sees(k, offset):
        """Does the f64 ray of fogplanes' camera through (x, y) meet light k, its origin moved
        where it enters the box as Mitsuba moves it (offset=True) or not?"""
        L = lights[k]
        corner, eu, ev = (np.array(L[key], dtype=float) for key in ("corner", "edge_u", "edge_v"))
        n = np.cross(eu, ev)

        def sees(x, y):
            d = cam.direction(x, y)
            o = cam.pos
            if offset and not inside:
                with np.errstate(divide="ignore", invalid="ignore"):
                    t0, t1 = (box_lo - o) / d, (box_hi - o) / d
                near, far = np.minimum(t0, t1), np.maximum(t0, t1)
                axis = int(np.argmax(near))  # the face it enters through
                t_in = near[axis]
                if 0 < t_in <= far.min():
                    p = o + t_in * d
                    normal = np.zeros(3)
                    normal[axis] = math.copysign(1.0, d[axis])
                    o = p + (1 + np.max(np.abs(p))) * RAY_EPSILON * normal
            t = ((corner - o) @ n) / (d @ n)
            if not t > 0:
                return False
            q = o + t * d - corner
            s, v = (q @ eu) / (eu @ eu), (q @ ev) / (ev @ ev)
            return 0 <= s <= 1 and 0 <= v <= 1
        return sees

    def crossing(sees, point, normal, reach=0.05):
        """The signed distance along `normal` (outward) where `sees` turns false, by bisection
        over [-reach, reach] pixels; None if the ends do not bracket one change."""
        lo, hi = -reach, reach
        at = lambda s: sees(*(point + s * normal))
        if not (at(lo) and not at(hi)):
            return None
        for _ in range(24):
            mid = 0.5 * (lo + hi)
            if at(mid):
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    ok, checked, skipped = True, 0, 0
    print(f"scene {a.scene}: distance of Mitsuba's outline from fogplanes' projected edge, pixels, "
          f"outward positive (mean over points {a.step:g} px apart; worst |.|)")
    print(f"{'light':<16}{'edge':>5}{'points':>7}{'no box: Mitsuba':>18}{'worst':>9}"
          f"{'with box: Mitsuba':>19}{'model':>10}{'worst |M-model|':>17}")
    for k, L in enumerate(lights):
        name = L.get("name", f"light {k}")
        corner, eu, ev = (np.array(L[key], dtype=float) for key in ("corner", "edge_u", "edge_v"))
        world = [corner, corner + eu, corner + eu + ev, corner + ev]
        if any((c - cam.pos) @ cam.f <= 0 for c in world):
            print(f"{name:<16} reaches behind the camera: skipped")
            continue
        quad = [cam.project(c) for c in world]
        centre = np.mean(quad, axis=0)
        bare_sees, box_sees = mitsuba_sees(without_box, k), mitsuba_sees(with_box, k)
        exact_sees, offset_sees = model_sees(k, False), model_sees(k, True)
        for e in range(4):
            p0, p1 = quad[e], quad[(e + 1) % 4]
            length = float(np.linalg.norm(p1 - p0))
            tangent = (p1 - p0) / length
            normal = np.array([tangent[1], -tangent[0]])
            if normal @ (p0 - centre) < 0:
                normal = -normal
            # Points along the edge, clear of the corners by half a pixel, inside the image.
            count = int((length - 1.0) // a.step) + 1
            rows = []
            for i in range(max(count, 0)):
                pt = p0 + (0.5 + (i + 0.5) * (length - 1.0) / count) * tangent
                if not (0.1 < pt[0] < w - 0.1 and 0.1 < pt[1] < h - 0.1):
                    continue
                found = [crossing(s, pt, normal) for s in (exact_sees, bare_sees, box_sees, offset_sees)]
                if any(f is None for f in found):
                    skipped += 1  # another panel in front, or the edge is not where the light is seen
                    continue
                rows.append([f - found[0] for f in found[1:]])
            checked += len(rows)
            if not rows:
                continue
            r = np.array(rows)
            bare, box, model = r[:, 0], r[:, 1], r[:, 2]
            worst_bare, worst_model = np.abs(bare).max(), np.abs(box - model).max()
            print(f"{name:<16}{e:>5}{len(r):>7}{bare.mean():>+18.5f}{worst_bare:>9.5f}"
                  f"{box.mean():>+19.5f}{model.mean():>+10.5f}{worst_model:>17.5f}")
            if worst_bare > a.tol:
                ok = False
                print(f"FAIL: without the box, {name} edge {e} lies {worst_bare:.5f} px from fogplanes' "
                      f"(limit {a.tol}): the export's camera or panel differs")
            if worst_model > a.tol:
                ok = False
                print(f"FAIL: with the box, {name} edge {e} lies {worst_model:.5f} px from the ray-offset "
                      f"model (limit {a.tol})")
    if checked == 0:
        ok = False
        print("FAIL: no outline point could be checked")
    print(f"{checked} points checked, {skipped} skipped (another panel in front, or no single crossing)")
    print("outlines: OK" if ok else "outlines: FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
