#!/usr/bin/env python3
"""The schedule model: how a render would run on N cores, from a record made on this machine.

    scripts/scaling_model.py [--binary target/release/fogplanes] [--planes 655360] [--threads 1,2,4,8,16,32,64]
                             [--record-threads 2]
    scripts/scaling_model.py --records DIR --from-records      # replay records made before

For each thread count N, renders the benchmark scene with `--schedule-record`: with
`--record-threads C`, on min(N, C) threads with the work cut for N workers
(`--schedule-workers N`: the tiles, units and barriers of N cores), each unit measured without
more threads than cores; without it, on N threads (each unit's time is its thread's CPU time,
so it is still measured alone, but beside N - 1 others that share the cores' caches). The record lists the render's sections: the units of one parallel loop, or one piece
of serial code, each section starting once the sections it waits for have ended
(`fogplanes::schedule`). The model replays the record made with N workers on N simulated
workers: a free worker takes the ready unit that became ready first (then in the order the
units started), a section's units become ready when every section it waits for has ended.

Predicted speedup at N = CPU seconds of the render's units with 1 worker / predicted wall
seconds with N. It leaves out what the record cannot see: memory bandwidth and caches shared
by more cores, and idle workers' spinning (their CPU time, not the wall time). A prediction,
never a measurement: docs/scaling says which figure is which.
"""

import argparse
import heapq
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections import Counter


def simulate(sections, workers):
    """Wall seconds of the record on `workers` simulated workers, and the busiest sections."""
    m = len(sections)
    waiting = [len(s["after"]) for s in sections]
    children = [[] for _ in range(m)]
    for i, s in enumerate(sections):
        for a in s["after"]:
            children[a].append(i)
    left = [len(s["units"]) for s in sections]
    ready = []  # (ready time, start order, section, seconds)
    running = []  # (end time, section)

    def release(i, t):
        if left[i] == 0:
            complete(i, t)
            return
        for seq, ns in sections[i]["units"]:
            heapq.heappush(ready, (t, seq, i, ns * 1e-9))

    def complete(i, t):
        for c in children[i]:
            waiting[c] -= 1
            if waiting[c] == 0:
                release(c, t)

    for i in range(m):
        if waiting[i] == 0:
            release(i, 0.0)
    t, free = 0.0, workers
    while ready or running:
        while free and ready:
            _, _, i, s = heapq.heappop(ready)
            heapq.heappush(running, (t + s, i))
            free -= 1
        end, i = heapq.heappop(running)
        t, free = end, free + 1
        left[i] -= 1
        if left[i] == 0:
            complete(i, t)
    return t


def cpu_seconds(sections):
    return sum(ns for s in sections for _, ns in s["units"]) * 1e-9


def record(binary, scene, args, threads, path):
    if args.reference:
        # The reference's units do not depend on the workers: each record on at most
        # --record-threads threads (default: N).
        cmd = [binary, "reference", scene, "--quiet", "--spp", str(args.reference), "--resolution", args.resolution,
               "--schedule-record", path, "--threads", str(min(threads, args.record_threads or threads))]
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run(cmd + ["-o", os.path.join(tmp, "x.exr")] + args.extra, check=True)
        return
    cmd = [binary, "render", scene, "--quiet", "--planes", str(args.planes),
           "-e", args.estimator, "--resolution", args.resolution, "--schedule-record", path]
    if args.record_threads:
        cmd += ["--threads", str(min(threads, args.record_threads)), "--schedule-workers", str(threads)]
    else:
        cmd += ["--threads", str(threads)]
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(cmd + ["-o", os.path.join(tmp, "x.exr")] + args.extra, check=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--binary", default="target/release/fogplanes")
    ap.add_argument("--scene", default="media_scenes/six_lights.toml")
    ap.add_argument("--planes", type=int, default=655_360)
    ap.add_argument("--resolution", default="640x360")
    ap.add_argument("-e", "--estimator", default="smis-exact")
    ap.add_argument("--threads", default="1,2,4,8,16,32,64")
    ap.add_argument("--records", help="directory of the records (kept); default: a temporary one")
    ap.add_argument("--from-records", action="store_true", help="replay the records in --records, render nothing")
    ap.add_argument("--record-threads", type=int, help="record with at most this many threads (the cores here), "
                    "the work cut for N workers (--schedule-workers N): no unit measured beside more threads than "
                    "cores; without it, each record runs N threads")
    ap.add_argument("--reference", type=int, metavar="SPP",
                    help="model the reference renderer (`fogplanes reference --spp SPP`) instead of a render")
    ap.add_argument("--repeat", type=int, default=1,
                    help="records per thread count; the medians of their CPU seconds and predicted walls are "
                    "reported (one record's units vary by a few percent on a shared machine)")
    ap.add_argument("--extra", nargs="*", default=[], help="further arguments for the renders")
    args = ap.parse_args()
    threads = [int(t) for t in args.threads.split(",")]
    if 1 not in threads:
        threads = [1] + threads
    tmp = None
    if args.records:
        os.makedirs(args.records, exist_ok=True)
        where = args.records
    else:
        tmp = tempfile.TemporaryDirectory()
        where = tmp.name
    records = {}
    for n in threads:
        records[n] = []
        for r in range(max(1, args.repeat)):
            path = os.path.join(where, f"record_{n}.json" if r == 0 else f"record_{n}_{r}.json")
            if not args.from_records:
                record(args.binary, args.scene, args, n, path)
            elif not os.path.exists(path):
                break
            with open(path) as f:
                records[n].append(json.load(f))
    one = statistics.median(cpu_seconds(r["sections"]) for r in records[1])
    r = records[1][0]
    print(f"{args.scene}: {r['estimator']}, {r['planes']} planes, {r['width']}x{r['height']}; "
          f"1 worker: {one:.2f} CPU s in {sum(len(s['units']) for s in r['sections'])} units"
          f" (medians of {len(records[1])} records)")
    print("| workers | units | sections | CPU s of the units | predicted wall s | predicted speedup | efficiency |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in threads:
        wall = statistics.median(simulate(r["sections"], n) for r in records[n])
        cpu = statistics.median(cpu_seconds(r["sections"]) for r in records[n])
        sections = records[n][0]["sections"]
        units = sum(len(s["units"]) for s in sections)
        print(f"| {n} | {units} | {len(sections)} | {cpu:.2f} | {wall:.3f} | "
              f"{one / wall:.2f}x | {one / wall / n:.0%} |")
    # Where the time of the largest record goes, section by section.
    last = max(threads)
    by = Counter()
    for s in records[last][0]["sections"]:
        by[s["label"]] += sum(ns for _, ns in s["units"]) * 1e-9
    print(f"CPU s by section at {last} workers: " + ", ".join(f"{k} {v:.3f}" for k, v in by.most_common()))
    if tmp:
        tmp.cleanup()


if __name__ == "__main__":
    sys.exit(main())
