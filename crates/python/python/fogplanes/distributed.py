"""Renders, references and sweeps on a Dask cluster, bit-identical to one machine's.

Needs Dask distributed (`pip install .[dask]`); `import fogplanes` alone never imports it.

    >>> import fogplanes, fogplanes.distributed
    >>> scene = fogplanes.load_scene("media_scenes/six_lights.toml")
    >>> image = fogplanes.distributed.render(scene, planes=10_000_000)  # doctest: +SKIP

Every function takes `client=None`: then it starts a `LocalCluster` of `workers` processes on
this machine (bound to 127.0.0.1) and closes it afterwards. Pass a
`distributed.Client` to use a cluster you started yourself: a scheduler address
(`Client("tcp://host:8786")`) or a batch queue (dask-jobqueue's `SLURMCluster`); docs/cluster.md
(the documentation's "On a cluster") shows all three. `client` is a Client, not an address: a string is a
TypeError (connect with `distributed.Client(address)`, which you then own and close).

Every function takes its `scene` as a `fogplanes.Scene` or the path of a scene file (str, bytes
or os.PathLike, as `open()` takes them), read on this machine: the workers get the scene, not the
path. Every argument is checked before any cluster starts or is asked anything: a bad one raises
ValueError (a bad value) or TypeError (a bad type) naming it; a scene file that cannot be opened
raises OSError; a client whose scheduler is gone (or that was closed) raises ValueError naming
the client.

How a render is spread (why the image does not depend on the cluster):

- The planes 0..N are cut into the core's canonical chunks (`plan_render`: a fixed power of
  two of planes, never derived from the number of workers). A task renders a block of chunks
  into a `Partial`: the chunks' unnormalised f64 sums. Plane i is the same plane wherever it
  is rendered (point i of the seed's scrambled Sobol sequence).
- Partials are added on the workers along the core's canonical binary tree over chunk indices
  (the same tree `fogplanes.render` uses), one task per step of the core's plan (`merge_plan`:
  a leaf renders a block of chunks, a node adds two earlier steps), and the last task divides
  by N and adds the direct emission (`finish_render`). Only the image reaches the
  client. The sums, and so the image, are the same bits for any number of workers, any order
  of completion and any retry or lost worker: equal to `fogplanes.render`'s.
- Tasks are submitted in the plan's post-order and the client keeps no future once it is
  added, so the scheduler frees each partial once its parent has added it: at most the tree's
  frontier is alive (about log2(tasks) + one per worker). Mind the size: a partial is
  height x width x 3 f64, 5.5 MB at 640x360 and about 200 MB at 3840x2160 (4K), on the worker
  that holds it.
- Task keys name the work (the scene's Dask token, the render's fingerprint, the plane range)
  and end with an id drawn for each call: a call's tasks are its own. Dask gives a key it
  still holds to whoever submits it again (its error, or its cancellation: the scheduler's
  report that a failed call's key was cancelled may reach the client after the next call has
  submitted that key), so shared keys let a failed call break a later one. Within a call each
  task is retried `retries` times if it raises, and a task lost with its worker is rerun by
  Dask under its key; two calls for the same image compute it twice. On any exception while
  waiting (KeyboardInterrupt included) the call's work is cancelled.

Threads: run one worker process per node with one Dask thread, and let each render use the
node's cores (`threads`). Dask sets OMP_NUM_THREADS for its workers but not rayon's thread
count, so a worker with k Dask threads whose renders each used every core would run k x cores
threads. `threads=None` gives each render the cores of its node divided by the Dask threads
there (the smallest over the nodes), and the local cluster also sets RAYON_NUM_THREADS.

GPUs: with `device="gpu"`, each worker gathers on the adapter its environment variable
FOGPLANES_GPU names (an index of `fogplanes.devices()` on its machine), which the launcher sets
per worker as dask-cuda sets CUDA_VISIBLE_DEVICES; where it is unset, on its machine's default
adapter (a real GPU first). A worker whose FOGPLANES_GPU names no adapter there fails the job,
and the client gets the worker's one-line ValueError (docs/gpu.md).
"""

from __future__ import annotations

import contextlib
import numbers
import os
import sys
import uuid
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from . import _fogplanes as native

try:
    import dask
    from dask.base import tokenize
    from distributed import Client, Future, LocalCluster
    from distributed.diagnostics.progressbar import TextProgressBar
except ImportError as e:  # pragma: no cover - exercised only without Dask
    raise ImportError(
        "fogplanes.distributed needs Dask distributed: pip install 'fogplanes[dask]' "
        "(or `pip install .[dask]` in the repository)"
    ) from e

__all__ = ["render", "render_future", "reference", "table", "local_client"]

#: Reference rows per task (a band); any split gives the same bits.
BAND_ROWS = 16
#: How many leaf tasks per Dask thread the automatic block size aims at (load balance).
TASKS_PER_SLOT = 8
#: Seconds a call waits for a first worker where the cluster has none: a batch system's workers
#: join after their jobs start, and on a loaded machine a local cluster's may be gone a moment
#: (CI once found none between a reference and a table on the same client).
WORKER_WAIT_SECONDS = 60

SceneArg = native.Scene | str | bytes | os.PathLike


# -- Arguments: every one checked before any cluster starts ---------------------------------------


def _scene(scene: SceneArg) -> native.Scene:
    """The scene of a `scene` argument: a `fogplanes.Scene`, or the path of a scene file (str,
    bytes or os.PathLike), read here (the workers get the scene: they need not see the file)."""
    if isinstance(scene, native.Scene):
        return scene
    if isinstance(scene, (str, bytes, os.PathLike)):
        return native.load_scene(scene)
    raise TypeError(f"scene: expected a fogplanes.Scene or the path of a scene file (str, bytes or os.PathLike), "
                    f"got {type(scene).__name__}")


def _int(name: str, value: Any, least: int) -> int:
    """An integer argument (not a bool) of at least `least`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name}={value!r}: expected an integer, got {type(value).__name__}")
    if value < least:
        raise ValueError(f"{name}={value!r}: must be an integer of at least {least}")
    return int(value)


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}={value!r}: expected True or False, got {type(value).__name__}")
    return bool(value)


def _block(chunks_per_task: Any) -> int | None:
    """`chunks_per_task`: None, or a power of two."""
    if chunks_per_task is None:
        return None
    if isinstance(chunks_per_task, bool) or not isinstance(chunks_per_task, numbers.Integral):
        raise TypeError(f"chunks_per_task={chunks_per_task!r}: expected a power of two (an integer) or None, "
                        f"got {type(chunks_per_task).__name__}")
    n = int(chunks_per_task)
    if n < 1 or n & (n - 1):
        raise ValueError(f"chunks_per_task={chunks_per_task!r}: must be a power of two (1, 2, 4, ...) or None")
    return n


def _gone(client: Client) -> str:
    address = getattr(client.scheduler, "address", None) or "its scheduler"
    return (f"client={client!r}: the Dask client is not connected to {address} (status {client.status!r}): "
            f"the scheduler is gone or the client was closed; connect a new distributed.Client")


def _client(client: Any, required: bool = False) -> Client | None:
    """`client`: a running `distributed.Client` (or None unless `required`)."""
    if client is None and not required:
        return None
    if not isinstance(client, Client):
        expected = "a distributed.Client" if required else "a distributed.Client or None"
        if isinstance(client, str):
            expected += " (connect to a scheduler's address with distributed.Client(address))"
        raise TypeError(f"client={client!r}: expected {expected}")
    if client.status != "running":
        raise ValueError(_gone(client))
    return client


def _check_layout(workers: Any, threads: Any) -> None:
    _int("workers", workers, 1)
    if threads is not None:
        _int("threads", threads, 1)


def _check_threads(scene: native.Scene, threads: int | None) -> None:
    """The core's range of `threads` (its check alone: no pool is started)."""
    if threads is not None:
        native.plan_render(scene, planes=1, threads=threads)


def _common(client: Any, workers: Any, threads: Any, progress: Any, retries: Any) -> None:
    """The arguments every function takes besides its scene and settings."""
    _client(client)
    _check_layout(workers, threads)
    _flag("progress", progress)
    _int("retries", retries, 0)


#: Render settings given by name (their values are checked by the core).
_NAMED_SETTINGS = ("estimator", "sampler", "accelerator", "kernel", "device")


def _render_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    """The settings given (None: not given), their types checked here so that a bad one is
    named (the core checks their values)."""
    if "threads" in kwargs:
        raise ValueError("threads is an argument of fogplanes.distributed.render itself")
    kwargs = {k: v for k, v in kwargs.items() if v is not None}
    for name in _NAMED_SETTINGS:
        if name in kwargs and not isinstance(kwargs[name], str):
            raise TypeError(f"{name}={kwargs[name]!r}: expected a name (a str), got {type(kwargs[name]).__name__}")
    if "pixel_center" in kwargs:
        _flag("pixel_center", kwargs["pixel_center"])
    return kwargs


def _call_id() -> str:
    """The id that ends the task keys of one call: 64 random bits."""
    return uuid.uuid4().hex[:16]


# -- The cluster ---------------------------------------------------------------------------------


def _cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _threads_per_task(client: Client) -> tuple[int, int]:
    """(threads per render, Dask threads in the cluster): each node's cores over its Dask
    threads, the smallest over the nodes, so that no node runs more render threads than cores.

    The cores are asked of the workers that answer: the scheduler may still list a worker that
    died (SIGKILLed, its machine gone) until it notices, and asking it once failed the whole
    call with the broadcast's CommClosedError. A worker that does not answer is left out here;
    the job's tasks go to the others, and to it again if it comes back."""
    workers = client.scheduler_info(n_workers=-1).get("workers")
    if workers is None:  # the client lost its scheduler (it then closes itself)
        raise ValueError(_gone(client))
    if not workers:
        try:
            client.wait_for_workers(1, timeout=WORKER_WAIT_SECONDS)
        except TimeoutError:
            raise ValueError(f"the Dask cluster has no workers (none joined in {WORKER_WAIT_SECONDS} s)") from None
        workers = client.scheduler_info(n_workers=-1).get("workers")
        if not workers:
            raise ValueError("the Dask cluster has no workers")
    cores = {address: n for address, n in client.run(_cores, on_error="return").items() if isinstance(n, int)}
    if not cores:
        raise ValueError(f"none of the Dask cluster's {len(workers)} workers answers")
    slots_by_host: dict[str, int] = {}
    cores_by_host: dict[str, int] = {}
    for address, info in workers.items():
        if address not in cores:
            continue
        host = info.get("host", address)
        slots_by_host[host] = slots_by_host.get(host, 0) + int(info["nthreads"])
        cores_by_host[host] = max(cores_by_host.get(host, 1), int(cores.get(address, 1)))
    threads = min(max(1, cores_by_host[h] // slots_by_host[h]) for h in slots_by_host)
    return threads, sum(slots_by_host.values())


@contextlib.contextmanager
def local_client(workers: int = 1, threads: int | None = None) -> Iterator[Client]:
    """A `LocalCluster` of `workers` processes, one Dask thread each, on 127.0.0.1 (the
    dashboard, if bokeh is installed, on a free port: `client.dashboard_link`), and its client;
    both closed on exit. Each worker's rayon pool gets `threads` (default: this machine's
    cores over `workers`) through RAYON_NUM_THREADS, and its allocator the command line's
    settings (`fogplanes.ALLOCATOR_ENVIRONMENT`, variables glibc reads as the process starts).

    Dask's nanny starts each worker with a trim threshold of 64 KiB
    (`distributed.nanny.pre-spawn-environ`), which hands a render's freed memory back at every
    piece and faults it in again (what that costs: docs/cluster.md, "The workers' allocator").
    These settings are the local cluster's own, over any of this process's environment or Dask
    configuration: a cluster of your own keeps its launcher's. The nanny writes its variables
    (and PYTHONHASHSEED) into this process's `os.environ` before it starts a worker, and takes
    a variable from there before its configuration (where a cluster this process started
    earlier left Dask's 64 KiB): ours are set there too while the cluster is made, and all of
    them put back as they were when it closes."""
    _check_layout(workers, threads)
    threads = threads or max(1, _cores() // workers)
    allocator = native.ALLOCATOR_ENVIRONMENT
    spawn = "distributed.nanny.pre-spawn-environ"
    before = {name: os.environ.get(name) for name in {*allocator, *dask.config.get(spawn), "PYTHONHASHSEED"}}
    try:
        os.environ.update(allocator)
        with dask.config.set({f"{spawn}.{name}": value for name, value in allocator.items()}):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address="127.0.0.1:0",  # a free port (its HTTP server runs even without the dashboard)
                env={"RAYON_NUM_THREADS": str(threads)},
            )
        try:
            with Client(cluster) as client:
                yield client
        finally:
            cluster.close()
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


@contextlib.contextmanager
def _session(client: Client | None, workers: int, threads: int | None) -> Iterator[tuple[Client, int, int]]:
    """(client, threads per render, Dask threads): the given client, or a local cluster."""
    if client is not None:
        auto, slots = _threads_per_task(client)
        yield client, threads or auto, slots
        return
    with local_client(workers, threads) as own:
        auto, slots = _threads_per_task(own)
        yield own, threads or auto, slots


class _StderrProgressBar(TextProgressBar):
    """Dask's text progress bar on stderr (stdout stays the caller's), labelled. On a terminal
    it is redrawn in place; elsewhere (a log file, a batch job's output) it writes a line per
    tenth of the tasks, never a carriage return."""

    def __init__(self, keys: Sequence[Any], label: str, **kwargs: Any) -> None:
        self.label = label
        self.tty = bool(getattr(sys.stderr, "isatty", lambda: False)())
        self.last_tenth = -1
        super().__init__(keys, **kwargs)

    def _draw_bar(self, remaining: int, all: int, **kwargs: Any) -> None:  # noqa: A002 (Dask's name)
        frac = (1 - remaining / all) if all else 1.0
        counts = f"{all - remaining}/{all} tasks | {self.elapsed:.1f} s"
        if self.tty:
            bar = "#" * int(self.width * frac)
            sys.stderr.write(f"\r{self.label} [{bar:<{self.width}}] {counts}")
        else:
            tenth = int(10 * frac)
            if tenth == self.last_tenth:
                return
            self.last_tenth = tenth
            sys.stderr.write(f"{self.label}: {100 * frac:3.0f}%, {counts}\n")
        sys.stderr.flush()

    def _draw_stop(self, **kwargs: Any) -> None:
        if self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()


def _wait(future: Future, progress: bool, label: str) -> Any:
    """The future's result, with a progress bar over it and every task it depends on. On
    any exception here (KeyboardInterrupt included) the work is cancelled: the scheduler then
    releases every task of the call (the client holds none but this one)."""
    try:
        if progress:
            _StderrProgressBar([future], label)
        return future.result()
    except BaseException:
        future.cancel()
        raise


# -- Renders -------------------------------------------------------------------------------------


def _auto_block(chunks: int, slots: int) -> int:
    """The largest power of two of chunks per task that leaves TASKS_PER_SLOT tasks per Dask
    thread (at least one chunk)."""
    target = max(1, chunks // (TASKS_PER_SLOT * max(1, slots)))
    return 1 << (target.bit_length() - 1)


def _render_block(scene: native.Scene, planes: tuple[int, int], threads: int,
                  kwargs: dict[str, Any]) -> native.Partial:
    return native.render_chunk(scene, planes, threads=threads, **kwargs)


def _add(left: native.Partial, right: native.Partial) -> native.Partial:
    # Two adjacent subtrees, checked (one render, left.end == right.start) and added in f64.
    return native.combine(left, right)


def _finish(scene: native.Scene, partial: native.Partial, kwargs: dict[str, Any],
            return_stats: bool) -> Any:
    return native.finish_render(scene, partial, return_stats=return_stats, **kwargs)


def _check_render(scene: SceneArg, render_kwargs: dict[str, Any], threads: int | None, retries: Any,
                  chunks_per_task: Any, return_stats: Any
                  ) -> tuple[native.Scene, dict[str, Any], dict[str, Any]]:
    """(scene, settings, plan) of a render, every argument checked."""
    scene = _scene(scene)
    kwargs = _render_kwargs(render_kwargs)
    plan = native.plan_render(scene, **kwargs)
    _check_threads(scene, threads)
    _int("retries", retries, 0)
    _block(chunks_per_task)
    _flag("return_stats", return_stats)
    return scene, kwargs, plan


def render_future(scene: SceneArg, client: Client, *, threads: int, slots: int = 1,
                  retries: int = 2, chunks_per_task: int | None = None,
                  return_stats: bool = False, **render_kwargs: Any) -> Future:
    """Submits a render to `client` and returns the future of its image (or (image, stats)):
    the tasks of `render` without waiting. `threads` is each task's render threads, `slots`
    the Dask threads of the cluster (for the automatic `chunks_per_task`). Every argument is
    checked before anything is submitted; the task keys are this call's own."""
    client = _client(client, required=True)
    _int("threads", threads, 1)
    _int("slots", slots, 1)
    scene, kwargs, plan = _check_render(scene, render_kwargs, threads, retries, chunks_per_task, return_stats)
    chunks = plan["chunks"]
    block = _block(chunks_per_task) or _auto_block(len(chunks), slots)
    stem = f"{tokenize(scene)}-{plan['fingerprint']}"
    call = _call_id()
    # The core's plan: leaves render blocks of chunks, nodes add two earlier steps (post-order).
    # A step's future is dropped once its parent is submitted: the scheduler keeps each
    # partial only until its parent has added it.
    steps: list[Future | None] = []
    for start, end, left, right in native.merge_plan(len(chunks), block):
        planes = (chunks[start][0], chunks[end - 1][1])
        if left is None:
            step = client.submit(_render_block, scene, planes, threads, kwargs, retries=retries,
                                 key=f"fogplanes-chunks-{stem}-{planes[0]}-{planes[1]}-{call}")
        else:
            step = client.submit(_add, steps[left], steps[right], retries=retries,
                                 key=f"fogplanes-add-{stem}-{planes[0]}-{planes[1]}-{call}")
            steps[left] = steps[right] = None
        steps.append(step)
    total = steps.pop()
    del steps
    return client.submit(_finish, scene, total, kwargs, return_stats, retries=retries,
                         key=f"fogplanes-finish-{stem}-{int(return_stats)}-{call}")


def render(scene: SceneArg, estimator: str | None = None, *, client: Client | None = None,
           workers: int = 1, threads: int | None = None, progress: bool = True,
           retries: int = 2, chunks_per_task: int | None = None, return_stats: bool = False,
           **render_kwargs: Any) -> Any:
    """Renders like `fogplanes.render(scene, estimator, **render_kwargs)`, on a Dask cluster:
    the same image, bit for bit, whatever the cluster.

    `scene`: a `fogplanes.Scene` or the path of a scene file. `client`: a
    `distributed.Client`; None starts a local cluster of `workers` processes for this call.
    `threads`: render threads per task (None: each node's cores over its Dask threads).
    `progress`: a text progress bar on stderr. `retries`: how many times a task that raises is
    retried (an integer >= 0). `chunks_per_task`: canonical chunks rendered by one task, a
    power of two (None: enough tasks for TASKS_PER_SLOT per Dask thread). The other arguments
    are `fogplanes.render`'s but `time_budget`, `target_error` (a distributed render has a plane
    count) and `return_stderr` (it makes no error image).
    Bad arguments raise ValueError or TypeError naming them before any cluster starts."""
    kwargs = dict(render_kwargs, estimator=estimator)
    _common(client, workers, threads, progress, retries)
    scene, _, _ = _check_render(scene, kwargs, threads, retries, chunks_per_task, return_stats)
    with _session(client, workers, threads) as (c, per_task, slots):
        future = render_future(scene, c, threads=per_task, slots=slots, retries=retries,
                               chunks_per_task=chunks_per_task, return_stats=return_stats,
                               **kwargs)
        return _wait(future, progress, "fogplanes render")


# -- References ----------------------------------------------------------------------------------


def _bands(height: int, rows: int) -> list[tuple[int, int]]:
    return [(j, min(j + rows, height)) for j in range(0, height, rows)]


def _pilot_band(scene: native.Scene, rows: tuple[int, int], threads: int,
                kwargs: dict[str, Any]) -> np.ndarray:
    return native.reference_pilot_rows(scene, rows, threads=threads, **kwargs)


def _counts(scene: native.Scene, kwargs: dict[str, Any], *pilot: np.ndarray) -> np.ndarray:
    return native.reference_counts(scene, np.concatenate(pilot, axis=0), **kwargs)


def _reference_band(scene: native.Scene, rows: tuple[int, int], threads: int,
                    kwargs: dict[str, Any], counts: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    return native.reference_rows(scene, rows, threads=threads, counts=counts, **kwargs)


def _stack(*bands: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return (np.concatenate([b[0] for b in bands], axis=0),
            np.concatenate([b[1] for b in bands], axis=0))


def reference(scene: SceneArg, spp: int | None = None, *, pixel_center: bool = False,
              resolution: tuple[int, int] | None = None, seed: int | None = None,
              uniform: bool = False, client: Client | None = None, workers: int = 1,
              threads: int | None = None, progress: bool = True, retries: int = 2,
              band_rows: int = BAND_ROWS) -> tuple[np.ndarray, np.ndarray]:
    """Renders like `fogplanes.reference(...)`, on a Dask cluster, in bands of `band_rows`
    rows: (image, per-pixel standard error), the same bits as one machine's (each pixel's
    random stream is keyed by the seed and the pixel). The adaptive mode (the default) runs
    the pilot in bands, the per-pixel counts in one task (the core's code), then the final
    bands. `scene`, `client`, `workers`, `threads`, `progress`, `retries` as in `render`."""
    scene = _scene(scene)
    _common(client, workers, threads, progress, retries)
    band_rows = _int("band_rows", band_rows, 1)
    uniform = _flag("uniform", uniform)
    kwargs = {k: v for k, v in dict(spp=spp, resolution=resolution, seed=seed).items() if v is not None}
    kwargs["pixel_center"] = _flag("pixel_center", pixel_center)
    # The errors before any cluster, by the core's checks: the resolution on the scene, the
    # settings on one pixel (its pilot costs milliseconds), the threads.
    if resolution is not None:
        if not isinstance(resolution, tuple) or len(resolution) != 2:
            raise TypeError(f"resolution={resolution!r}: expected (width, height), got {type(resolution).__name__}")
        for side in resolution:  # named as fogplanes.reference names them
            if isinstance(side, bool) or not isinstance(side, numbers.Integral):
                raise TypeError(f"resolution={side!r}: expected an integer, got {type(side).__name__}")
        scene_at = scene.with_resolution(*resolution)
    else:
        scene_at = scene
    native.reference_pilot_rows(scene, (0, 1), **dict(kwargs, resolution=(1, 1)))
    _check_threads(scene, threads)
    bands = _bands(scene_at.resolution[1], band_rows)
    stem = f"{tokenize(scene)}-{tokenize(kwargs, uniform)}-{_call_id()}"
    with _session(client, workers, threads) as (c, per_task, _):
        counts = None
        if not uniform:
            pilot = [c.submit(_pilot_band, scene, rows, per_task, kwargs, retries=retries,
                              key=f"fogplanes-pilot-{stem}-{rows[0]}-{rows[1]}") for rows in bands]
            counts = c.submit(_counts, scene, kwargs, *pilot, retries=retries,
                              key=f"fogplanes-counts-{stem}")
            del pilot
        final = dict(kwargs, uniform=uniform)
        parts = [c.submit(_reference_band, scene, rows, per_task, final, counts, retries=retries,
                          key=f"fogplanes-reference-{stem}-{rows[0]}-{rows[1]}") for rows in bands]
        del counts
        whole = c.submit(_stack, *parts, retries=retries, key=f"fogplanes-stack-{stem}")
        del parts
        return _wait(whole, progress, "fogplanes reference")


# -- Sweeps --------------------------------------------------------------------------------------


def _row(scene: native.Scene, ref: np.ndarray, estimator: str, planes: int | None,
         seed: int | None, threads: int, kwargs: dict[str, Any]) -> dict[str, Any]:
    image, stats = native.render(scene, estimator, planes=planes, seed=seed, threads=threads,
                                 return_stats=True, **kwargs)
    metrics = native.compare(image, ref)
    return {
        "estimator": stats["estimator"],
        "planes": stats["planes"],
        "seed": seed,
        **{k: metrics[k] for k in ("smape", "mse", "rel_mse", "max_abs")},
        "hits": stats["hits"],
        "seconds": stats["seconds_total"],
    }


def _listed(name: str, value: Any, default: Iterable[Any], kind: type, what: str) -> list[Any]:
    """A sweep's axis `name`: one value of `kind` (`what`: "a name (a str)", "an integer"), or
    an iterable of them (a list, a tuple, a range, an array), each of its type (not a bool);
    None: `default`. Their values are the core's to check."""
    if value is None:
        return list(default)
    if isinstance(value, kind) and not isinstance(value, bool):
        return [value]
    if isinstance(value, (str, bytes, bool)) or not isinstance(value, Iterable):
        raise TypeError(f"{name}={value!r}: expected {what} or a list of them, got {type(value).__name__}")
    items = list(value)
    for i, item in enumerate(items):
        if isinstance(item, bool) or not isinstance(item, kind):
            raise TypeError(f"{name}[{i}]={item!r}: expected {what}, got {type(item).__name__}")
    return items


def _check_image(image: np.ndarray, what: str) -> None:
    """Refuses, before any cluster starts, an image its workers would refuse: a dtype that is
    not real, or a value that is not a finite float32 (named by its pixel and channel)."""
    if image.dtype.kind not in "biuf":
        raise TypeError(f"{what}: expected an array of a real dtype, got dtype {image.dtype}")
    with np.errstate(over="ignore"):
        finite = np.isfinite(image.astype(np.float32))
    if not finite.all():
        y, x, c = (int(i) for i in np.argwhere(~finite)[0])
        raise ValueError(f"{what}: pixel (x {x}, y {y}) channel {'RGB'[c]} is {image[y, x, c]!r}, "
                         "not a finite number (as float32)")


def table(scene: SceneArg, reference: Any, estimators: str | Iterable[str] | None = None,
          planes: int | Iterable[int] | None = None, seeds: int | Iterable[int] | None = None, *,
          client: Client | None = None, workers: int = 1, threads: int | None = None,
          progress: bool = True, retries: int = 2, **render_kwargs: Any) -> list[dict[str, Any]]:
    """A sweep as tasks: one `fogplanes.render` per estimator x planes x seed (in that order),
    each compared with `reference` on its worker by `fogplanes.compare`; only the numbers come
    back, one dict per render: estimator, planes, seed, smape, mse, rel_mse, max_abs, hits,
    seconds (the render's wall time on its worker). The reference (an image, a path, or the
    (image, stderr) pair of `reference`) is sent to every worker once. `estimators` default to
    every estimator, `planes` and `seeds` to the scene's (a row's `planes` and `seed` are those
    it rendered, the scene's where none was given; its `estimator` is the render's label, such
    as "smis-exact-k4" with `orientations=4`); the other keyword arguments are
    `fogplanes.render`'s but `time_budget`, `target_error` (each render has a plane count),
    `return_stats` and `return_stderr` (a row holds the numbers). `scene`, `client`, `workers`,
    `threads`, `progress`, `retries` as in `render`; the reference must have the renders' shape
    (height, width, 3)."""
    scene = _scene(scene)
    _common(client, workers, threads, progress, retries)
    for axis in ("estimator", "seed"):  # the sweep's own: a single one is a list of one
        if axis in render_kwargs:
            raise TypeError(f"unexpected keyword argument '{axis}': table sweeps {axis}s= (one or a list)")
    for key in ("time_budget", "target_error"):
        if render_kwargs.get(key) is not None:
            raise ValueError(f"{key}: each of a table's renders has a plane count; give planes= (one or a list)")
    kwargs = _render_kwargs(render_kwargs)
    runs = [(e, n, s) for e in _listed("estimators", estimators, native.ESTIMATORS, str, "a name (a str)")
            for n in _listed("planes", planes, [None], numbers.Integral, "an integer")
            for s in _listed("seeds", seeds, [None], numbers.Integral, "an integer")]
    shapes = set()
    for k, (e, n, s) in enumerate(runs):  # every setting checked before any cluster
        plan = native.plan_render(scene, **_render_kwargs(dict(estimator=e, planes=n, seed=s)), **kwargs)
        shapes.add(tuple(plan["shape"]))
        runs[k] = (e, n, plan["seed"])  # the scene's seed, where none is given, named in its row
    _check_threads(scene, threads)
    if isinstance(reference, tuple) and len(reference) == 2:  # reference()'s (image, stderr)
        reference = reference[0]
    if isinstance(reference, (str, bytes, os.PathLike)):
        reference = native.load_image(reference)
    try:
        ref = np.asarray(reference)
    except (TypeError, ValueError) as e:  # a ragged list
        raise type(e)(f"reference: {e}") from e
    if ref.ndim == 0:  # a number, None, ...: numpy makes an array of anything
        raise TypeError(f"reference: expected an image (an array of shape (height, width, 3)), its path, or "
                        f"reference()'s (image, stderr) pair, got {type(reference).__name__}")
    for shape in shapes:
        if ref.shape != shape:
            raise ValueError(f"reference: expected an image of the renders' shape {shape}, "
                             f"got shape {ref.shape}")
    _check_image(ref, "reference")
    stem = f"{tokenize(scene, ref, kwargs)}-{_call_id()}"
    with _session(client, workers, threads) as (c, per_task, _):
        # A key of this call's own (hash=False: a random one), not one of the reference's content,
        # which every call with that reference shared: a call that released it took it from
        # the tasks of the next ("lost dependencies").
        shared_ref = c.scatter(ref, broadcast=True, hash=False)
        rows = [c.submit(_row, scene, shared_ref, e, n, s, per_task, kwargs, retries=retries,
                         key=f"fogplanes-table-{stem}-{e}-{n}-{s}") for e, n, s in runs]
        try:
            if progress:
                _StderrProgressBar(rows, "fogplanes table")
            return c.gather(rows)
        except BaseException:
            c.cancel(rows)
            raise
