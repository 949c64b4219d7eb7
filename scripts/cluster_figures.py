#!/usr/bin/env python3
"""The figures of the README's section "On a cluster": fogplanes.distributed on this machine.

Needs the module and Dask: `pip install .[dask]` in a virtual environment. Three measures, each
printed as a Markdown table row:

  throughput PLANES [RUNS]   planes/s of a distributed render on a running local cluster of
                             1 worker process (1 thread), 2 worker processes (1 thread each)
                             and 1 process of 2 render threads, against plain
                             `fogplanes.render` with 1 and 2 threads; median of RUNS runs
                             taken in turn (A B C A B C ...), so a shared machine's load
                             falls on all alike.
  overhead PLANES [RUNS]     wall seconds of plain `fogplanes.render` (all cores) against
                             `fogplanes.distributed.render` with its own local cluster (one
                             process of all cores: started, used, closed, as a user calls it),
                             in turn, medians; the difference is the cluster's overhead.
  reference SPP [RUNS]       samples per second per core of the reference (uniform, 640x360),
                             and what that gives for a 65,536-spp 1280x720 reference on
                             16 nodes of CORES cores (environment variable, default 32).

  scripts/cluster_figures.py throughput 1310720 3
  scripts/cluster_figures.py overhead 40960 5
  scripts/cluster_figures.py reference 64 3
"""

import os
import statistics
import sys
import time
from pathlib import Path

import fogplanes
import fogplanes.distributed as fd
from distributed import Client, LocalCluster

SCENE = Path(__file__).resolve().parents[1] / "media_scenes" / "six_lights.toml"


def timed(fn):
    start = time.perf_counter()
    result = fn()
    return time.perf_counter() - start, result


def in_turn(named, runs):
    """Median wall seconds of each callable, run in turn `runs` times."""
    seconds = {name: [] for name in named}
    for _ in range(runs):
        for name, fn in named.items():
            seconds[name].append(timed(fn)[0])
    return {name: statistics.median(s) for name, s in seconds.items()}


def cluster(workers, threads):
    local = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                         dashboard_address=None, env={"RAYON_NUM_THREADS": str(threads)})
    return local, Client(local)


def throughput(planes, runs):
    scene = fogplanes.load_scene(SCENE)
    kwargs = dict(planes=planes, pixel_center=True)
    layouts = {"1 process x 1 thread": (1, 1), "2 processes x 1 thread": (2, 1),
               "1 process x 2 threads": (1, 2)}
    clusters = {name: cluster(*layout) for name, layout in layouts.items()}
    reference_image = fogplanes.render(scene, threads=2, **kwargs)
    try:
        named = {f"plain render, {t} thread{'s' * (t > 1)}": (lambda t=t: fogplanes.render(scene, threads=t, **kwargs))
                 for t in (1, 2)}
        for name, (local, client) in clusters.items():
            threads = layouts[name][1]
            named[f"distributed, {name}"] = lambda c=client, t=threads: check(
                fd.render(scene, client=c, threads=t, progress=False, **kwargs), reference_image)
        medians = in_turn(named, runs)
    finally:
        for local, client in clusters.values():
            client.close()
            local.close()
    print(f"| {planes:,} planes, 640x360, median of {runs} | seconds | planes/s |")
    print("|---|---:|---:|")
    for name, s in medians.items():
        print(f"| {name} | {s:.2f} | {planes / s:,.0f} |")


def check(image, expected):
    assert image.tobytes() == expected.tobytes(), "the distributed image differs"
    return image


def overhead(planes, runs):
    scene = fogplanes.load_scene(SCENE)
    kwargs = dict(planes=planes, pixel_center=True)
    expected = fogplanes.render(scene, **kwargs)
    medians = in_turn({
        "plain": lambda: fogplanes.render(scene, **kwargs),
        "distributed": lambda: check(fd.render(scene, workers=1, progress=False, **kwargs), expected),
    }, runs)
    extra = medians["distributed"] - medians["plain"]
    print(f"| {planes:,} | {medians['plain']:.2f} | {medians['distributed']:.2f} | {extra:+.2f} "
          f"({100 * extra / medians['plain']:+.0f}%) |")


def reference(spp, runs):
    scene = fogplanes.load_scene(SCENE)
    cores = len(os.sched_getaffinity(0))
    width, height = scene.resolution
    seconds = statistics.median(
        timed(lambda: fogplanes.reference(scene, spp=spp, uniform=True, pixel_center=True))[0]
        for _ in range(runs))
    per_core = spp * width * height / seconds / cores
    node_cores = int(os.environ.get("CORES", "32"))
    target = 65536 * 1280 * 720
    one = target / per_core / node_cores
    print(f"reference: {spp} spp at {width}x{height} in {seconds:.2f} s on {cores} cores: "
          f"{per_core:.3e} samples/s per core")
    print(f"65,536 spp at 1280x720 = {target:.3e} samples: {one / 3600:.2f} h on one node of {node_cores} "
          f"cores, {one / 16 / 60:.1f} min on 16 such nodes (ideal; the bands are independent)")


if __name__ == "__main__":
    what, amount = sys.argv[1], int(sys.argv[2])
    runs = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    {"throughput": throughput, "overhead": overhead, "reference": reference}[what](amount, runs)
