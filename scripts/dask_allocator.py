"""What the Dask workers' allocator settings cost a render (docs/cluster.md, "The workers'
allocator"): one worker of THREADS threads started as Dask starts it (a plain `LocalCluster`,
whose nanny sets glibc's trim threshold to 64 KiB) and as `fogplanes.distributed.local_client`
starts it (`fogplanes.ALLOCATOR_ENVIRONMENT`), alternated ROUNDS times; in each, one render to
warm it, then four of each size, and the worker's own CPU seconds, system seconds and page
faults a render (`getrusage` on the worker).

    python scripts/dask_allocator.py [ROUNDS [THREADS]]     (default 2 rounds, 2 threads)

Needs the module and Dask distributed (`pip install .[dask]`); run from the repository's root.
"""

import contextlib
import resource
import sys
import time

from distributed import Client, LocalCluster

import fogplanes
import fogplanes.distributed as fd

SCENE = "media_scenes/six_lights.toml"
RENDERS = 4
SIZES = [("40,960 planes at 640x360", dict(planes=40_960)),
         ("655,360 planes at 32x18", dict(planes=655_360, resolution=(32, 18)))]


def usage() -> tuple[float, float, int]:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime, r.ru_stime, r.ru_minflt


@contextlib.contextmanager
def dasks_own(threads: int):
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0", env={"RAYON_NUM_THREADS": str(threads)})
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def measure(name: str, cluster, threads: int) -> None:
    with cluster(threads) as client:
        scene = fogplanes.load_scene(SCENE)
        fd.render(scene, client=client, progress=False, **SIZES[0][1])
        for size, kwargs in SIZES:
            (cpu, sys_, faults), start = list(client.run(usage).values())[0], time.time()
            for _ in range(RENDERS):
                fd.render(scene, client=client, progress=False, **kwargs)
            cpu2, sys2, faults2 = list(client.run(usage).values())[0]
            print(f"{name:22} {size}: {(time.time() - start) / RENDERS:.3f} s of wall time a render, "
                  f"the worker's CPU {(cpu2 - cpu) / RENDERS:.3f} s (system {(sys2 - sys_) / RENDERS:.3f} s), "
                  f"{(faults2 - faults) / RENDERS:,.0f} page faults", flush=True)


if __name__ == "__main__":
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 2
    threads = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    for _ in range(rounds):
        measure("Dask's settings", dasks_own, threads)
        measure("fogplanes' settings", lambda t: fd.local_client(1, t), threads)
