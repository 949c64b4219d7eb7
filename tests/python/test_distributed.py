"""Tests of `fogplanes.distributed` on a local Dask cluster: 2 worker processes of 1 thread each,
on 127.0.0.1, no dashboard. CI installs Dask (.ci/requirements.txt); without it every test
here is reported SKIPPED with the reason.

The images must be the same bits as one machine's: for any number of workers, chunks per
task, completion order and lost worker.
"""

import asyncio
import os
import pickle
import reprlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip(
    "distributed",
    reason="SKIPPED LOUDLY: Dask distributed is not installed (pip install .[dask]); "
    "fogplanes.distributed is untested here",
)

from dask.base import tokenize  # noqa: E402 (after the skip)
from distributed import Client, LocalCluster  # noqa: E402

import fogplanes  # noqa: E402
import fogplanes.distributed as fd  # noqa: E402

from helpers import SIX_LIGHTS, assert_bit_identical  # noqa: E402

# Seconds a killed worker's nanny may take to bring it back. A wait, not a tolerance: on a
# loaded 2-core machine a new worker process once took over 60 s to import Dask and fogplanes.
WORKER_RESTART = 240


@pytest.fixture(scope="module")
def scene():
    return fogplanes.load_scene(SIX_LIGHTS)


@pytest.fixture(scope="module")
def client():
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0", env={"RAYON_NUM_THREADS": "1"})
    with Client(cluster) as c:
        yield c
    cluster.close()


def chunk_planes(scene) -> int:
    return fogplanes.plan_render(scene, planes=1)["chunk_planes"]


def local_merge(scene, **kwargs) -> np.ndarray:
    """The canonical chunks rendered here one by one, merged (given in reverse: the merge
    sorts them) and finished."""
    plan = fogplanes.plan_render(scene, **kwargs)
    parts = [fogplanes.render_chunk(scene, chunk, **kwargs) for chunk in plan["chunks"]]
    return fogplanes.finish_render(scene, fogplanes.merge_partials(parts[::-1]), **kwargs)


# -- Renders -------------------------------------------------------------------------------------

def test_import_fogplanes_does_not_import_dask():
    code = ("import sys, fogplanes; assert 'dask' not in sys.modules and 'distributed' not in sys.modules; "
            "fogplanes.distributed; assert 'distributed' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


@pytest.mark.parametrize("settings", [
    dict(estimator="smis-exact", spp=2, pixel_center=False),
    dict(estimator="unweighted", sampler="independent", seed=7, pixel_center=True),
], ids=["smis-exact-spp2", "unweighted-independent"])
def test_render_is_the_same_bits_for_1_and_2_workers_as_the_local_merge_and_render(client, scene, settings):
    # Six canonical chunks, the last one short: a ragged tree.
    kwargs = dict(settings, resolution=(64, 36), planes=5 * chunk_planes(scene) + 1234)
    two = [fd.render(scene, client=client, threads=1, chunks_per_task=block, progress=False, **kwargs)
           for block in (1, 2, 4)]
    one = fd.render(scene, workers=1, threads=1, progress=False, **kwargs)  # its own LocalCluster
    for image in (*two[1:], one, local_merge(scene, **kwargs), fogplanes.render(scene, **kwargs)):
        assert_bit_identical(two[0], image)
    assert np.all(np.isfinite(one)) and one.mean() > 0


def test_forward_fog_with_any_share_of_lobes_is_one_machines_on_two_workers(client):
    """The lobes' share (`lobes=`) reaches every worker: in fog that scatters forward (g = 0.85)
    the cluster's image is one machine's at each share, and the shares' images differ."""
    forward_fog = fogplanes.load_scene(SIX_LIGHTS.parent / "forward_fog.toml")
    kwargs = dict(resolution=(48, 30), planes=2 * chunk_planes(forward_fog) + 777)
    images = []
    for lobes in (0.0, 0.25, None):
        image = fd.render(forward_fog, client=client, threads=1, chunks_per_task=1, progress=False,
                          lobes=lobes, **kwargs)
        assert_bit_identical(image, fogplanes.render(forward_fog, lobes=lobes, **kwargs))
        images.append(image)
    for i in range(len(images)):
        for j in range(i):
            assert not np.array_equal(images[i], images[j]), (i, j)


def test_the_local_clusters_workers_keep_freed_memory_as_the_command_line_does(client, monkeypatch):
    settings = dict(fogplanes.ALLOCATOR_ENVIRONMENT)
    assert set(settings) == {"MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_"}
    assert all(int(v) >= 1 << 20 for v in settings.values()), settings
    # As a plain LocalCluster of this process (`client`'s) leaves it: Dask's trim threshold in
    # the environment, which a nanny takes before its configuration. And nothing of the
    # nanny's own, so that what local_client leaves behind shows.
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    monkeypatch.delenv("MALLOC_MMAP_THRESHOLD_", raising=False)
    monkeypatch.delenv("PYTHONHASHSEED", raising=False)
    before = dict(os.environ)

    def started_with(names):
        """The worker's variables as its process started, when glibc read them (Linux), else
        as they are now."""
        try:
            with open("/proc/self/environ", "rb") as f:
                env = dict(e.decode().split("=", 1) for e in f.read().split(b"\0") if b"=" in e)
        except OSError:
            env = dict(os.environ)
        return {name: env.get(name) for name in names}

    with fd.local_client(1, 1) as own:
        seen = own.run(started_with, list(settings))
    assert list(seen.values()) == [settings]
    assert dict(os.environ) == before, "this process's environment is put back"


def test_a_worker_killed_mid_render_changes_no_bit(client, scene):
    kwargs = dict(resolution=(64, 36), planes=32 * chunk_planes(scene))
    future = fd.render_future(scene, client, threads=1, chunks_per_task=1, **kwargs)
    deadline = time.monotonic() + 60
    while True:  # until a worker holds a partial
        held = {w: keys for w, keys in client.has_what().items() if keys}
        if held or time.monotonic() > deadline:
            break
        time.sleep(0.01)
    assert held and not future.done(), "the render ended before a worker could be killed: make it longer"
    victim = max(held, key=lambda w: len(held[w]))
    pids = client.run(os.getpid)
    os.kill(pids[victim], signal.SIGKILL)
    image = future.result(timeout=120)
    assert_bit_identical(image, fogplanes.render(scene, threads=2, **kwargs))
    client.wait_for_workers(2, timeout=WORKER_RESTART)  # the nanny restarted it
    assert pids[victim] not in client.run(os.getpid).values()


def test_a_client_that_lost_a_worker_renders_references_and_tables_with_the_same_bits(client, scene):
    """An idle worker SIGKILLed, then at once render, reference and table on the same client,
    5 rounds in a row: each the bits of the plain function. (The first call after the kill
    once failed in 23 of 25 rounds: the cores were asked of every worker the scheduler still
    listed, the dead one too, and the broadcast's CommClosedError ended the call.)"""
    size = dict(resolution=(32, 18))
    kwargs = dict(size, planes=3 * chunk_planes(scene) + 77)
    plain = fogplanes.render(scene, **kwargs)
    ref_kwargs = dict(size, spp=16, uniform=True)
    plain_ref = fogplanes.reference(scene, **ref_kwargs)
    ref = plain_ref[0]
    plain_row = fogplanes.compare(fogplanes.render(scene, "smis-exact", planes=500, seed=1, **size), ref)
    for round in range(5):
        client.wait_for_workers(2, timeout=WORKER_RESTART)
        pids = client.run(os.getpid)
        victim = sorted(pids)[round % 2]
        os.kill(pids[victim], signal.SIGKILL)
        image = fd.render(scene, client=client, threads=1, progress=False, **kwargs)
        assert_bit_identical(image, plain)
        mean, stderr = fd.reference(scene, client=client, threads=1, band_rows=6, progress=False, **ref_kwargs)
        assert_bit_identical(mean, plain_ref[0])
        assert_bit_identical(stderr, plain_ref[1])
        rows = fd.table(scene, ref, estimators=["smis-exact"], planes=[500], seeds=[1], client=client, threads=1,
                        progress=False, **size)
        assert {k: rows[0][k] for k in ("smape", "mse", "rel_mse", "max_abs")} == {
            k: plain_row[k] for k in ("smape", "mse", "rel_mse", "max_abs")}, f"round {round}"
    client.wait_for_workers(2, timeout=WORKER_RESTART)


def test_a_pickled_scene_renders_identically(client, scene):
    small = scene.with_resolution(48, 27)
    copy = pickle.loads(pickle.dumps(small))
    assert tokenize(copy) == tokenize(small) != tokenize(scene)
    kwargs = dict(planes=chunk_planes(scene) + 5)
    image = fd.render(copy, client=client, threads=1, progress=False, **kwargs)
    assert image.shape == (27, 48, 3)
    assert_bit_identical(image, fogplanes.render(small, **kwargs))
    assert_bit_identical(image, fogplanes.render(copy, **kwargs))


def test_task_keys_name_the_work_and_are_each_calls_own(client, scene):
    kwargs = dict(resolution=(32, 18), planes=3000)
    a = fd.render_future(scene, client, threads=1, **kwargs)
    b = fd.render_future(pickle.loads(pickle.dumps(scene)), client, threads=1, kernel="portable", **kwargs)
    c = fd.render_future(scene, client, threads=1, **dict(kwargs, seed=2))

    def work(key):  # the key without the call's id
        return key.rsplit("-", 1)[0]

    # Each call its own keys; the work they name: the kernel changes no bit, the seed does.
    assert a.key != b.key and work(a.key) == work(b.key) != work(c.key)
    plan = fogplanes.plan_render(scene, **kwargs)
    assert work(a.key) == f"fogplanes-finish-{tokenize(scene)}-{plan['fingerprint']}-0"
    assert_bit_identical(a.result(), b.result())


def test_the_progress_bar_is_on_stderr(client, scene, capfd):
    fd.render(scene, client=client, threads=1, resolution=(32, 18), planes=2 * chunk_planes(scene) + 1)
    out, err = capfd.readouterr()
    # 3 chunks (one per task: too few for more), 2 additions (the core's plan) and the finish.
    assert len(fogplanes.merge_plan(3, 1)) + 1 == 6
    # Captured, stderr is not a terminal: a line per tenth at most, never a carriage return
    # (a log file got 667 redrawn bars).
    lines = err.splitlines()
    assert out == "" and "\r" not in err and "fogplanes render: 100%, 6/6 tasks" in err, err
    assert 1 <= len([line for line in lines if line.startswith("fogplanes render:")]) <= 11, err


def test_merge_refuses_mismatched_parts(scene):
    kwargs = dict(resolution=(32, 18), planes=2 * chunk_planes(scene))
    first, second = fogplanes.plan_render(scene, **kwargs)["chunks"]
    a = fogplanes.render_chunk(scene, first, **kwargs)
    b = fogplanes.render_chunk(scene, second, **kwargs)
    other_seed = fogplanes.render_chunk(scene, second, **dict(kwargs, seed=2))
    with pytest.raises(ValueError):
        fogplanes.merge_partials([a, other_seed])  # another render's part
    with pytest.raises(ValueError):
        fogplanes.merge_partials([a, a])  # overlapping ranges
    with pytest.raises(ValueError):
        fogplanes.finish_render(scene, a, **kwargs)  # planes missing
    with pytest.raises(ValueError):
        fd._add(b, a)  # not adjacent in this order
    whole = fogplanes.finish_render(scene, fogplanes.merge_partials([b, a]), **kwargs)
    assert_bit_identical(whole, fogplanes.render(scene, **kwargs))


# Bad arguments of every function: (keyword arguments, the exception, a word its message must
# hold: the argument's name). Each is refused before any cluster starts.
BAD_COMMON = [
    (dict(retries="x"), TypeError, "retries"),
    (dict(retries=-1), ValueError, "retries"),
    (dict(retries=True), TypeError, "retries"),
    (dict(client="tcp://127.0.0.1:8786"), TypeError, "client"),
    (dict(client=object()), TypeError, "client"),
    (dict(workers=0), ValueError, "workers"),
    (dict(workers=True), TypeError, "workers"),
    (dict(workers=1.5), TypeError, "workers"),
    (dict(threads=0), ValueError, "threads"),
    (dict(threads=5000), ValueError, "threads"),
    (dict(threads="2"), TypeError, "threads"),
    (dict(progress="yes"), TypeError, "progress"),
]
BAD_RENDER_SETTINGS = [
    (dict(planes=0), ValueError, "planes"),
    (dict(planes=-5), ValueError, "planes"),
    (dict(estimator="nope"), ValueError, "estimator"),
    (dict(estimator=5), TypeError, "estimator"),
    (dict(sampler=1), TypeError, "sampler"),
    (dict(kernel=3), TypeError, "kernel"),
    (dict(accelerator=b"bvh"), TypeError, "accelerator"),
    (dict(pixel_center="no"), TypeError, "pixel_center"),
    (dict(resolution=(0, 5)), ValueError, "resolution"),
    (dict(time_budget=1.0), ValueError, "time_budget"),
    (dict(colour=1), TypeError, "colour"),
]
BAD_RENDER = BAD_COMMON + BAD_RENDER_SETTINGS + [
    (dict(chunks_per_task=3), ValueError, "chunks_per_task"),
    (dict(chunks_per_task=0), ValueError, "chunks_per_task"),
    (dict(chunks_per_task=-4), ValueError, "chunks_per_task"),
    (dict(chunks_per_task=True), TypeError, "chunks_per_task"),
    (dict(chunks_per_task=2.0), TypeError, "chunks_per_task"),
    (dict(return_stats=1), TypeError, "return_stats"),
]
BAD_RENDER_FUTURE = [case for case in BAD_RENDER if not {"client", "workers", "progress"} & case[0].keys()] + [
    (dict(threads=None), TypeError, "threads"),
    (dict(slots=0), ValueError, "slots"),
    (dict(slots="4"), TypeError, "slots"),
]
BAD_REFERENCE = BAD_COMMON + [
    (dict(spp=0), ValueError, "spp"),
    (dict(spp=-1), ValueError, "spp"),
    (dict(resolution=(0, 5)), ValueError, "resolution"),
    (dict(resolution=(8, 6, 3)), TypeError, "resolution"),
    (dict(resolution="8x6"), TypeError, "resolution"),
    (dict(resolution=[8, 6]), TypeError, "resolution"),
    (dict(seed=-1), ValueError, "seed"),
    (dict(band_rows=0), ValueError, "band_rows"),
    (dict(band_rows=2.5), TypeError, "band_rows"),
    (dict(uniform="yes"), TypeError, "uniform"),
    (dict(pixel_center="no"), TypeError, "pixel_center"),
]
BAD_TABLE = BAD_COMMON + [
    (dict(estimators=["smis-exact", "nope"]), ValueError, "estimator"),
    (dict(estimators=[5]), TypeError, "estimator"),
    (dict(planes=[1000, 0]), ValueError, "planes"),
    (dict(seeds=[1, -1]), ValueError, "seed"),
    (dict(reference=np.zeros((6, 9, 3), np.float32)), ValueError, "reference"),
    (dict(reference="missing.exr"), FileNotFoundError, "missing.exr"),
    # Refused by every task, three times each with the workers' tracebacks, before these.
    (dict(reference=np.full((6, 8, 3), np.nan, np.float32)), ValueError, "reference: pixel (x 0, y 0) channel R"),
    (dict(reference=np.full((6, 8, 3), 1e39)), ValueError, "not a finite number (as float32)"),
    (dict(reference=np.ones((6, 8, 3), complex)), TypeError, "reference: expected an array of a real dtype"),
    (dict(pixel_center="no"), TypeError, "pixel_center"),
    (dict(kernel=3), TypeError, "kernel"),
]


def test_every_bad_argument_raises_naming_it_before_any_cluster_starts(scene, client, monkeypatch):
    def refuse(*args, **kwargs):
        pytest.fail("a cluster was started or asked for bad arguments")

    monkeypatch.setattr(fd, "LocalCluster", refuse)
    monkeypatch.setattr(client, "submit", refuse)
    monkeypatch.setattr(client, "scheduler_info", refuse)
    monkeypatch.setattr(client, "run", refuse)
    size = dict(resolution=(8, 6))
    calls = (
        [(fd.render, dict(size, planes=100, progress=False), case) for case in BAD_RENDER]
        + [(lambda **k: fd.render_future(scene, client, **k), dict(size, threads=1, planes=100), case)
           for case in BAD_RENDER_FUTURE]
        + [(fd.reference, dict(size, spp=4, progress=False), case) for case in BAD_REFERENCE]
        + [(fd.table, dict(size, reference=np.zeros((6, 8, 3), np.float32), planes=100, progress=False), case)
           for case in BAD_TABLE]
    )
    wrong = []  # every case that did not raise as it should, reported at once
    for function, good, (bad, error, name) in calls:
        args = () if function.__name__ == "<lambda>" else (scene,)
        try:
            function(*args, **{**good, **bad})
            wrong.append(f"{function.__name__}({reprlib.repr(bad)}): no error")
        except BaseException as e:  # noqa: B036 (pytest.fail's exception too)
            if not isinstance(e, error) or name not in str(e):
                wrong.append(f"{function.__name__}({reprlib.repr(bad)}): {type(e).__name__}: {str(e)[:100]}")
    assert not wrong, "\n".join(wrong)
    for scene_arg, error in ((42, TypeError), (None, TypeError), ("missing.toml", FileNotFoundError)):
        for function in (fd.render, fd.reference):
            with pytest.raises(error, match="scene|missing.toml"):
                function(scene_arg, resolution=(8, 6), progress=False)
        with pytest.raises(error, match="scene|missing.toml"):
            fd.table(scene_arg, np.zeros((6, 8, 3), np.float32), resolution=(8, 6), progress=False)
        with pytest.raises(error, match="scene|missing.toml"):
            fd.render_future(scene_arg, client, threads=1, resolution=(8, 6))
    with pytest.raises(TypeError, match="client"):
        fd.render_future(scene, "tcp://127.0.0.1:8786", threads=1)
    for bad in (dict(workers=0), dict(threads=0), dict(workers="2")):
        with pytest.raises((ValueError, TypeError), match=next(iter(bad))):
            with fd.local_client(**bad):
                pass


@pytest.mark.parametrize(
    "call, error, says",
    [
        # Was "'float' object is not iterable": neither the argument nor what it takes.
        (lambda s, r: fd.table(s, r, planes=2048.0), TypeError,
         r"^planes=2048\.0: expected an integer or a list of them, got float$"),
        (lambda s, r: fd.table(s, r, seeds=1.0), TypeError,
         r"^seeds=1\.0: expected an integer or a list of them, got float$"),
        (lambda s, r: fd.table(s, r, planes="2048"), TypeError,
         r"^planes='2048': expected an integer or a list of them, got str$"),
        (lambda s, r: fd.table(s, r, planes=True), TypeError,
         r"^planes=True: expected an integer or a list of them, got bool$"),
        # Were named as the render's estimator= and planes=, not as the list's item.
        (lambda s, r: fd.table(s, r, estimators=5), TypeError,
         r"^estimators=5: expected a name \(a str\) or a list of them, got int$"),
        (lambda s, r: fd.table(s, r, estimators=["smis-exact", 5]), TypeError,
         r"^estimators\[1\]=5: expected a name \(a str\), got int$"),
        (lambda s, r: fd.table(s, r, planes=[1000, 2.5]), TypeError,
         r"^planes\[1\]=2\.5: expected an integer, got float$"),
        # Was "plan_render() got multiple values for keyword argument 'seed'".
        (lambda s, r: fd.table(s, r, seed=3), TypeError, r"^unexpected keyword argument 'seed': table sweeps seeds="),
        # A scene path as bytes was refused ("scene: expected ... (str or os.PathLike), got bytes"):
        # it is read, and the bad count named.
        (lambda s, r: fd.table(os.fsencode(SIX_LIGHTS), r, spp=4.0), TypeError,
         r"^spp=4\.0: expected an integer, got float$"),
        # Were ValueError "expected an image of the renders' shape (6, 8, 3), got shape ()".
        (lambda s, r: fd.table(s, 5), TypeError,
         r"^reference: expected an image \(an array of shape \(height, width, 3\)\), "
                                                 r"its path, or reference\(\)'s \(image, stderr\) pair, got int$"),
        (lambda s, r: fd.table(s, None), TypeError, r"^reference: expected an image .* got NoneType$"),
        # Was an IndexError.
        (lambda s, r: fd.table(s, ()), ValueError,
         r"^reference: expected an image of the renders' shape \(6, 8, 3\), got shape \(0,\)$"),
        (lambda s, r: fd.table(s, [[1.0, 2.0], [3.0]]), ValueError,
         r"^reference: setting an array element with a sequence"),
        # Were "planes: expected an integer (TypeError: 'float' object cannot be interpreted as an integer)".
        (lambda s, r: fd.render(s, planes=2048.0), TypeError, r"^planes=2048\.0: expected an integer, got float$"),
        (lambda s, r: fd.render(s, seed=1.0), TypeError, r"^seed=1\.0: expected an integer, got float$"),
        (lambda s, r: fd.reference(s, 16.0), TypeError, r"^spp=16\.0: expected an integer, got float$"),
        (lambda s, r: fd.reference(s, 16, resolution=(8.0, 6)), TypeError,
         r"^resolution=8\.0: expected an integer, got float$"),
        (lambda s, r: fd.render(s, workers=2.0), TypeError, r"^workers=2\.0: expected an integer, got float$"),
        (lambda s, r: fd.reference(s, 16, band_rows=2.0), TypeError,
         r"^band_rows=2\.0: expected an integer, got float$"),
    ],
)
def test_the_counts_and_the_reference_of_a_sweep_are_named_as_given(scene, monkeypatch, call, error, says):
    def refuse(*args, **kwargs):
        pytest.fail("a cluster was started for bad arguments")

    monkeypatch.setattr(fd, "LocalCluster", refuse)
    with pytest.raises(error, match=says):
        call(scene.with_resolution(8, 6), np.zeros((6, 8, 3), np.float32))


def test_a_client_whose_scheduler_is_gone_is_named(scene):
    cluster = LocalCluster(n_workers=0, processes=False, dashboard_address=":0")  # in-process, no worker
    gone = Client(cluster)
    cluster.close()  # the scheduler is gone: the client closes itself (it used to be KeyError 'workers')
    size = dict(resolution=(8, 6))
    for call in (lambda: fd.render(scene, client=gone, planes=100, progress=False, **size),
                 lambda: fd.reference(scene, spp=4, client=gone, progress=False, **size),
                 lambda: fd.table(scene, np.zeros((6, 8, 3), np.float32), client=gone, progress=False, **size),
                 lambda: fd.render_future(scene, gone, threads=1, planes=100, **size)):
        with pytest.raises(ValueError, match=r"client.*scheduler"):
            call()
    gone.close()


def test_every_function_takes_a_scene_or_the_path_of_its_file(client, scene):
    size = dict(resolution=(16, 9))
    render = dict(size, planes=chunk_planes(scene) + 3)
    expected = fogplanes.render(scene, **render)
    expected_ref = fogplanes.reference(scene, spp=4, **size)
    for path in (str(SIX_LIGHTS), SIX_LIGHTS):
        assert_bit_identical(fd.render(path, client=client, threads=1, progress=False, **render), expected)
        assert_bit_identical(fd.render_future(path, client, threads=1, **render).result(), expected)
        mean, stderr = fd.reference(path, spp=4, client=client, threads=1, progress=False, **size)
        assert_bit_identical(mean, expected_ref[0])
        assert_bit_identical(stderr, expected_ref[1])
        [row] = fd.table(path, expected_ref, estimators="unweighted", planes=500, seeds=1, client=client,
                         threads=1, progress=False, **size)
        assert row["estimator"] == "unweighted" and row["planes"] == 500 and row["smape"] > 0


def _late_cancellation_reports(client, monkeypatch, wait=0.5):
    """Makes the scheduler's report that keys were cancelled reach the client late, as a slow
    network or a busy scheduler may: after the client has submitted tasks under those keys again
    (or after `wait` seconds, if it does not), the other reports not held back."""
    handle = client._stream_handlers["cancelled-keys"]

    def late(keys, **kwargs):
        async def deliver():
            deadline = time.monotonic() + wait
            while not all(k in client.futures for k in keys) and time.monotonic() < deadline:
                await asyncio.sleep(0.001)
            handle(keys=keys, **kwargs)

        asyncio.ensure_future(deliver())

    monkeypatch.setitem(client._stream_handlers, "cancelled-keys", late)


def test_a_failed_render_leaves_the_client_clean_for_the_next(client, scene, monkeypatch):
    # A failed render cancels its last task; the scheduler reports the cancellation to the
    # client, which cancels whatever future it then holds under that key. Were the next render's
    # keys the same, a late report would cancel it (FutureCancelledError for fogplanes-finish-...).
    kwargs = dict(resolution=(32, 18), planes=2 * chunk_planes(scene) + 1)
    expected = fogplanes.render(scene, **kwargs)
    _late_cancellation_reports(client, monkeypatch)
    for _ in range(2):
        with monkeypatch.context() as m:
            m.setattr(fd, "_render_block", fd._add)  # every block raises TypeError on its worker
            with pytest.raises(TypeError):
                fd.render(scene, client=client, threads=1, retries=0, chunks_per_task=1, progress=False,
                          **kwargs)
        image = fd.render(scene, client=client, threads=1, chunks_per_task=1, progress=False, **kwargs)
        assert_bit_identical(image, expected)


def test_a_failed_render_future_still_held_does_not_poison_the_next(client, scene, monkeypatch):
    # While a future is alive its client keeps the key's state (here: erred) and gives it to
    # whoever submits the key again.
    kwargs = dict(resolution=(32, 18), planes=chunk_planes(scene) + 1)
    with monkeypatch.context() as m:
        m.setattr(fd, "_render_block", fd._add)
        failed = fd.render_future(scene, client, threads=1, retries=0, **kwargs)
        with pytest.raises(TypeError):
            failed.result()
    again = fd.render_future(scene, client, threads=1, **kwargs)  # `failed` is still held
    assert_bit_identical(again.result(), fogplanes.render(scene, **kwargs))
    assert failed.status == "error"


# -- References and sweeps -----------------------------------------------------------------------

@pytest.mark.parametrize("uniform", [False, True], ids=["adaptive", "uniform"])
def test_reference_is_the_same_bits_as_one_machines(client, scene, uniform):
    kwargs = dict(spp=32, resolution=(48, 27), seed=5, uniform=uniform, pixel_center=uniform)
    mean, stderr = fd.reference(scene, client=client, threads=1, band_rows=5, progress=False, **kwargs)
    one_mean, one_stderr = fogplanes.reference(scene, **kwargs)
    assert_bit_identical(mean, one_mean)
    assert_bit_identical(stderr, one_stderr)
    assert np.all(stderr > 0)


def test_table_computes_the_metrics_on_the_workers(client, scene):
    size = dict(resolution=(48, 27), pixel_center=True)
    ref, _ = fogplanes.reference(scene, spp=64, **size)
    rows = fd.table(scene, ref, estimators=["unweighted", "smis-exact"], planes=[500, 1000], seeds=[1, 2],
                    client=client, threads=1, progress=False, **size)
    assert [(r["estimator"], r["planes"], r["seed"]) for r in rows] == [
        (e, n, s) for e in ("unweighted", "smis-exact") for n in (500, 1000) for s in (1, 2)]
    for r in rows:
        expected = fogplanes.compare(fogplanes.render(scene, r["estimator"], planes=r["planes"], seed=r["seed"],
                                                      **size), ref)
        assert {k: r[k] for k in ("smape", "mse", "rel_mse", "max_abs")} == {
            k: expected[k] for k in ("smape", "mse", "rel_mse", "max_abs")}
        assert r["hits"] > 0 and r["seconds"] >= 0


def test_tables_called_again_with_one_reference_each_keep_their_own(scene):
    """The reference is scattered under a key of the call's own: under one of its content
    (hash=True), every call with that reference shared the key, and a call that released it
    took it from the next call's tasks ("lost dependencies": 3 of 6 calls failed in a row).
    Without seeds, a row names the scene's seed it rendered, not None."""
    size = dict(resolution=(32, 18))
    ref = fogplanes.render(scene, planes=40960, **size)
    first = None
    # fogplanes.distributed's own cluster, where the race showed (the module's client, of one
    # thread a worker, seldom lost it).
    with fd.local_client(workers=2) as own:
        for _ in range(6):
            [row] = fd.table(scene, ref, estimators=["smis-exact"], planes=[1024], client=own, progress=False,
                             **size)
            assert row["seed"] == scene.render.seed and row["planes"] == 1024, row
            first = first or row
            assert {k: row[k] for k in ("smape", "mse", "hits")} == {k: first[k] for k in ("smape", "mse", "hits")}


def test_a_tables_renders_have_a_plane_count_and_a_finished_render_names_its_devices(scene):
    size = dict(resolution=(16, 9), pixel_center=True)
    for key, value in (("time_budget", 0.5), ("target_error", 0.1)):
        with pytest.raises(ValueError, match=rf"^{key}: each of a table's renders has a plane count; give planes="):
            fd.table(scene, np.zeros((9, 16, 3), np.float32), progress=False, **{key: value}, **size)
    plan = fogplanes.plan_render(scene, planes=256, **size)
    parts = [fogplanes.render_chunk(scene, chunk, planes=256, **size) for chunk in plan["chunks"]]
    _, stats = fogplanes.finish_render(scene, fogplanes.merge_partials(parts), True, planes=256, **size)
    _, own = fogplanes.render(scene, planes=256, return_stats=True, **size)
    assert stats["device"] == own["device"] == "cpu" and stats["devices"] == ["cpu"], stats


def _gpu_or_skip():
    if fogplanes.devices():
        return
    if os.environ.get("FOGPLANES_REQUIRE_GPU") == "1":
        raise AssertionError("FOGPLANES_REQUIRE_GPU=1 but fogplanes.devices() finds no GPU adapter")
    pytest.skip("SKIPPED LOUDLY: no GPU adapter here; install mesa-vulkan-drivers")


def test_a_gpu_render_on_two_workers_is_one_machines(scene, client):
    """`device="gpu"` on two workers (each its adapter: the default one, or FOGPLANES_GPU's where
    the launcher sets it) gives one machine's GPU image bit for bit."""
    _gpu_or_skip()
    kwargs = dict(resolution=(16, 9), planes=2 * chunk_planes(scene) + 100, device="gpu")
    image = fd.render(scene, client=client, threads=1, progress=False, chunks_per_task=1, **kwargs)
    assert_bit_identical(image, fogplanes.render(scene, **kwargs))


def test_a_worker_without_its_adapter_fails_the_job_with_a_clear_error_at_the_client(scene):
    """A worker whose FOGPLANES_GPU names an adapter it does not have fails the job, and the
    client is told why in one line (the count of adapters there)."""
    _gpu_or_skip()
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0",
                           env={"RAYON_NUM_THREADS": "1", "FOGPLANES_GPU": "99"})
    try:
        with Client(cluster) as c, pytest.raises(ValueError, match=r"FOGPLANES_GPU=99: there (is|are) \d+ adapter"):
            fd.render(scene, client=c, threads=1, progress=False, retries=0, resolution=(16, 9), planes=256,
                      device="gpu")
    finally:
        cluster.close()


def test_a_call_waits_for_a_first_worker_and_names_a_cluster_that_never_has_one(scene, monkeypatch):
    """A cluster without workers yet (a batch system's jobs still queued, or a loaded machine's
    workers a moment gone) is waited for: a worker that joins meanwhile renders the image. One
    that never has any is named, after the wait (it was refused at once)."""
    kwargs = dict(resolution=(16, 9), planes=300, progress=False)
    cluster = LocalCluster(n_workers=0, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0", env={"RAYON_NUM_THREADS": "1"})
    try:
        with Client(cluster) as c:
            monkeypatch.setattr(fd, "WORKER_WAIT_SECONDS", 1)
            with pytest.raises(ValueError, match=r"^the Dask cluster has no workers \(none joined in 1 s\)$"):
                fd.render(scene, client=c, threads=1, **kwargs)
            monkeypatch.setattr(fd, "WORKER_WAIT_SECONDS", WORKER_RESTART)
            cluster.scale(1)  # the worker starts in the background, seconds from now
            image = fd.render(scene, client=c, threads=1, **kwargs)
            assert_bit_identical(image, fogplanes.render(scene, **{k: v for k, v in kwargs.items() if k != "progress"}))
    finally:
        cluster.close()
