#!/usr/bin/env python3
"""CPU seconds of whole renders, two builds side by side in one run.

    scripts/compare_builds.py OLD_BINARY NEW_BINARY [--runs 5] [--config smis-exact ...]

Each configuration renders the benchmark scene (media_scenes/six_lights.toml, 640x360, 40,960
planes, 2 threads) with both binaries, alternating old and new run by run so that the noise of a
shared machine falls on both alike. Reports the median CPU seconds (user + system of the whole
command) of each, the ratio new / old, and each build's ratio to its own smis-exact and
unweighted. A configuration is an estimator name, optionally with `:K` orientations
(smis-exact:4). Timings are reported, never asserted.

`--new-scene` renders another scene with the new binary (the old one keeps `--scene`): a key the
old build does not know, such as `[medium] g = 0.8`, measured against the old build's image of
the same lights and planes. For the same hits give the new scene `[render] lobes = 0` too: g
alone changes a hit's value, not which hits there are, but the planes' lobes (docs/mathematics.md
section 2.5) sweep a share of the planes elsewhere.
"""

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile

DEFAULT_CONFIGS = ["unweighted", "cmis-cosine", "smis-cosine", "smis-exact", "smis-exact:4", "smis-exact:8", "cmis-exact"]


def cpu_seconds(binary, scene, config, extra):
    estimator, _, k = config.partition(":")
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [binary, "render", scene, "--threads", "2", "--quiet", "-e", estimator, "-o", os.path.join(tmp, "x.exr")]
        if k:
            cmd += ["--orientations", k]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(cmd + extra, check=True, stdout=subprocess.DEVNULL)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--scene", default="media_scenes/six_lights.toml")
    ap.add_argument("--new-scene", default=None, help="the new binary's scene (default: --scene)")
    ap.add_argument("--config", nargs="*", default=DEFAULT_CONFIGS)
    ap.add_argument("--extra", nargs="*", default=[], help="further arguments for both renders")
    args = ap.parse_args()
    medians = {}
    for config in args.config:
        times = {"old": [], "new": []}
        for _ in range(args.runs):
            for name in ("old", "new"):
                scene = args.new_scene if name == "new" and args.new_scene else args.scene
                times[name].append(cpu_seconds(getattr(args, name), scene, config, args.extra))
        medians[config] = {n: statistics.median(t) for n, t in times.items()}
        m = medians[config]
        print(
            f"{config:14} old {m['old']:6.2f} s  new {m['new']:6.2f} s  new/old {m['new'] / m['old']:.2f}"
            f"   (old runs {' '.join(f'{t:.2f}' for t in times['old'])}; new {' '.join(f'{t:.2f}' for t in times['new'])})",
            flush=True,
        )
    for base in ("smis-exact", "unweighted"):
        if base not in medians:
            continue
        print(f"\nCPU time relative to {base} of the same build:")
        for config, m in medians.items():
            print(f"{config:14} old {m['old'] / medians[base]['old']:5.2f}x  new {m['new'] / medians[base]['new']:5.2f}x")


if __name__ == "__main__":
    sys.exit(main())
