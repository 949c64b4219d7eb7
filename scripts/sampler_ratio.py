#!/usr/bin/env python3
"""MSE of Sobol planes against independent planes, for the figures of docs/measurements.md.

Uses only the built command line (cargo build --release). Two measures:

  vsref:  the mean over SEEDS plane sets of the MSE against a reference EXR, minus the
          reference's own noise MSE (NOISE, printed by `fogplanes reference`), and each image
          mean (compare it with the reference's to see that both samplers are unbiased);
  pairs:  the variance of the estimate from pairs of independent seeds (MSE between two renders
          / 2; needs no reference, since both samplers are unbiased).

  scripts/sampler_ratio.py vsref REF.exr NOISE ESTIMATORS SEEDS PLANES
  scripts/sampler_ratio.py pairs RESOLUTION ESTIMATORS SEEDS PLANES[,PLANES..]

e.g. scripts/sampler_ratio.py vsref ref640.exr 1.087e-7 smis-exact 8 40960
     scripts/sampler_ratio.py pairs 160x90 smis-exact 16 10240,40960,655360
"""
import json, re, statistics, subprocess, sys, tempfile

BIN = "target/release/fogplanes"
SCENE = "media_scenes/six_lights.toml"


def render(out, planes, seed, estimator, sampler, resolution=None):
    args = [BIN, "render", SCENE, "--pixel-center", "--planes", str(planes), "--seed", str(seed),
            "-e", estimator, "--sampler", sampler, "--quiet", "-o", out]
    if resolution:
        args += ["--resolution", resolution]
    o = subprocess.run(args, capture_output=True, text=True, check=True)
    return float(re.search(r"mean ([0-9.e+-]+)", o.stdout).group(1))


def mse(a, b):
    o = subprocess.run([BIN, "compare", a, b, "--json"], capture_output=True, text=True, check=True)
    return json.loads(o.stdout)["mse"]


def mean_se(xs):
    return statistics.mean(xs), statistics.stdev(xs) / len(xs) ** 0.5


def vsref(ref, noise, estimators, seeds, planes):
    d = tempfile.mkdtemp()
    for e in estimators:
        got = {}
        for sampler in ("independent", "sobol"):
            errors, means = [], []
            for s in range(seeds):
                means.append(render(f"{d}/x.exr", planes, 101 + s, e, sampler))
                errors.append(mse(f"{d}/x.exr", ref))
            (m, se), (im, ise) = mean_se(errors), mean_se(means)
            got[sampler] = m
            print(f"{e:12} {sampler:12} {planes} MSE {m:.4e} +- {se:.1e} (minus noise {m - noise:.4e}); "
                  f"image mean {im:.7f} +- {ise:.1e}", flush=True)
        print(f"RATIO {e} {planes} {(got['sobol'] - noise) / (got['independent'] - noise):.3f}", flush=True)


def pairs(resolution, estimators, seeds, counts):
    d = tempfile.mkdtemp()
    for e in estimators:
        for planes in counts:
            var = {}
            for sampler in ("independent", "sobol"):
                for s in range(seeds):
                    render(f"{d}/{s}.exr", planes, 1 + 7919 * s, e, sampler, resolution)
                v = [mse(f"{d}/{s}.exr", f"{d}/{s + 1}.exr") / 2 for s in range(0, seeds - 1, 2)]
                var[sampler] = mean_se(v)
                print(f"{e:12} {sampler:12} {planes:7} variance {var[sampler][0]:.4e} +- {var[sampler][1]:.1e} "
                      f"(N x variance {planes * var[sampler][0]:.4e})", flush=True)
            print(f"RATIO {e} {planes} {var['sobol'][0] / var['independent'][0]:.3f}", flush=True)


if __name__ == "__main__":
    if len(sys.argv) == 7 and sys.argv[1] == "vsref":
        vsref(sys.argv[2], float(sys.argv[3]), sys.argv[4].split(","), int(sys.argv[5]), int(sys.argv[6]))
    elif len(sys.argv) == 6 and sys.argv[1] == "pairs":
        pairs(sys.argv[2], sys.argv[3].split(","), int(sys.argv[4]), [int(n) for n in sys.argv[5].split(",")])
    else:
        sys.exit(__doc__)
