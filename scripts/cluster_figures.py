#!/usr/bin/env python3
"""The figures of docs/cluster.md ("On a cluster"): fogplanes.distributed on this machine.

Needs the module and Dask: `pip install .[dask]` in a virtual environment. Three measures,
printed as Markdown tables:

  throughput PLANES [RUNS]   planes/s (wall and CPU) of a distributed render on a running local cluster of
                             1 worker process (1 thread), 2 worker processes (1 thread each)
                             and 1 process of 2 render threads, against plain
                             `fogplanes.render` with 1 and 2 threads; median of RUNS runs
                             taken in turn (A B C A B C ...), so a shared machine's load
                             falls on all alike.
  overhead PLANES [RUNS]     plain `fogplanes.render` (2 threads) against
                             `fogplanes.distributed.render` on a running local cluster (one
                             process, 2 render threads: wall and CPU seconds, the worker's
                             included) and with its own cluster (started, used and closed,
                             as a user calls it without a client: wall seconds), in turn,
                             medians; the differences are the cluster's overhead.
  reference SPP [RUNS]       samples per CPU second of the reference (uniform, whole pixels, 640x360), and
                             what that gives for a 65,536-spp 1280x720 reference on 16 nodes
                             of CORES cores (environment variable, default 32).

CPU seconds (user + system, every process involved) hold on a shared machine where wall
seconds do not; each table says the load average around it.

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
import psutil
import fogplanes.distributed as fd
from distributed import Client, LocalCluster

SCENE = Path(__file__).resolve().parents[1] / "media_scenes" / "six_lights.toml"


def cpu_seconds(clients):
    """User + system CPU seconds of this process (the client, and a local cluster's scheduler
    and nannies) and of the worker processes of `clients`, so far."""
    own = psutil.Process().cpu_times()
    total = own.user + own.system
    for client in clients:
        total += sum(client.run(lambda: sum(psutil.Process().cpu_times()[:2])).values())
    return total


def timed(fn, clients=()):
    """(wall seconds, CPU seconds, result) of fn()."""
    cpu, start = cpu_seconds(clients), time.perf_counter()
    result = fn()
    return time.perf_counter() - start, cpu_seconds(clients) - cpu, result


def in_turn(named, runs):
    """Median (wall, CPU) seconds of each (callable, clients whose workers it uses), run in
    turn `runs` times."""
    seconds = {name: [] for name in named}
    for _ in range(runs):
        for name, (fn, clients) in named.items():
            seconds[name].append(timed(fn, clients)[:2])
    return {name: tuple(statistics.median(x) for x in zip(*s)) for name, s in seconds.items()}


def load():
    return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"


def cluster(workers, threads):
    local = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                         dashboard_address="127.0.0.1:0", env={"RAYON_NUM_THREADS": str(threads)})
    return local, Client(local)


def throughput(planes, runs):
    scene = fogplanes.load_scene(SCENE)
    kwargs = dict(planes=planes)  # whole pixels, 16 ray sets (the default)
    layouts = {"1 process x 1 thread": (1, 1), "2 processes x 1 thread": (2, 1),
               "1 process x 2 threads": (1, 2)}
    clusters = {name: cluster(*layout) for name, layout in layouts.items()}
    reference_image = fogplanes.render(scene, threads=2, **kwargs)
    try:
        named = {f"plain render, {t} thread{'s' * (t > 1)}": (lambda t=t: fogplanes.render(scene, threads=t, **kwargs), [])
                 for t in (1, 2)}
        for name, (local, client) in clusters.items():
            threads = layouts[name][1]
            named[f"distributed, {name}"] = (lambda c=client, t=threads: check(
                fd.render(scene, client=c, threads=t, progress=False, **kwargs), reference_image), [client])
        before = load()
        medians = in_turn(named, runs)
    finally:
        for local, client in clusters.values():
            client.close()
            local.close()
    print(f"{before} before, {load()} after")
    print(f"| {planes:,} planes, 640x360, whole pixels, median of {runs} | wall s | planes/s | CPU s | planes per CPU s |")
    print("|---|---:|---:|---:|---:|")
    for name, (wall, cpu) in medians.items():
        print(f"| {name} | {wall:.2f} | {planes / wall:,.0f} | {cpu:.2f} | {planes / cpu:,.0f} |")


def check(image, expected):
    assert image.tobytes() == expected.tobytes(), "the distributed image differs"
    return image


def overhead(planes, runs):
    scene = fogplanes.load_scene(SCENE)
    kwargs = dict(planes=planes)  # whole pixels, 16 ray sets (the default)
    expected = fogplanes.render(scene, threads=2, **kwargs)
    local, client = cluster(1, 2)
    try:
        before = load()
        medians = in_turn({
            "plain": (lambda: fogplanes.render(scene, threads=2, **kwargs), []),
            "running cluster": (lambda: check(fd.render(scene, client=client, progress=False, **kwargs),
                                              expected), [client]),
            "own cluster": (lambda: check(fd.render(scene, workers=1, progress=False, **kwargs), expected), []),
        }, runs)
    finally:
        client.close()
        local.close()
    (wall, cpu), (rwall, rcpu), (owall, _) = (medians[k] for k in ("plain", "running cluster", "own cluster"))
    print(f"{before} before, {load()} after; 2 render threads, median of {runs}")
    print("| planes | plain: wall s, CPU s | on a running cluster: wall s, CPU s | with its own cluster: wall s |")
    print(f"| {planes:,} | {wall:.2f}, {cpu:.2f} | {rwall:.2f} ({rwall - wall:+.2f}), {rcpu:.2f} ({rcpu - cpu:+.2f}) "
          f"| {owall:.2f} ({owall - wall:+.2f}) |")


def reference(spp, runs):
    scene = fogplanes.load_scene(SCENE)
    width, height = scene.resolution
    cpu = statistics.median(
        timed(lambda: fogplanes.reference(scene, spp=spp, uniform=True))[1]
        for _ in range(runs))
    per_core = spp * width * height / cpu
    node_cores = int(os.environ.get("CORES", "32"))
    target = 65536 * 1280 * 720
    one = target / per_core / node_cores
    print(f"reference: {spp} spp at {width}x{height}, uniform, {cpu:.2f} CPU s: {per_core:.3e} samples per "
          f"CPU second, whole pixels ({load()})")
    print(f"65,536 spp at 1280x720 = {target:.3e} samples: {one / 3600:.2f} h on one node of {node_cores} "
          f"cores, {one / 16 / 60:.1f} min on 16 such nodes (ideal; the bands are independent)")


if __name__ == "__main__":
    what, amount = sys.argv[1], int(sys.argv[2])
    runs = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    {"throughput": throughput, "overhead": overhead, "reference": reference}[what](amount, runs)
