"""The Python doors of issue 26 ("trust nothing that comes from a file, a pickle, a worker or a
caller"): arguments of the wrong type named as given, bools refused where counts are asked for,
row pairs checked before any conversion, unpickled partials and given-back arrays (pilots, sample
counts) held to what the library can make. Each raised, or returned NaN, before the fix."""

import os
import pickle
import subprocess
import sys
import threading

import numpy as np
import pytest

import fogplanes
from helpers import ROOT, SIX_LIGHTS

SMALL = dict(resolution=(8, 6))
CHUNKED = dict(planes=20000, resolution=(8, 6))


@pytest.fixture(scope="module")
def scene():
    return fogplanes.load_scene(SIX_LIGHTS)


@pytest.mark.parametrize(
    "kwargs, error, says",
    [
        # A TypeError that named nothing ("'int' object cannot be converted to 'PyString'").
        (dict(estimator=5), TypeError, r"^estimator=5: expected a name \(a str\), got int$"),
        (dict(sampler=1.5), TypeError, r"^sampler=1.5: expected a name"),
        (dict(pixel_center="x"), TypeError, r"^pixel_center='x': expected True or False, got str$"),
        (dict(return_stats=1), TypeError, r"^return_stats=1: expected True or False, got int$"),
        # Bools were counts: spp=True rendered one ray set.
        (dict(spp=True), TypeError, r"^spp=True: expected an integer, got bool$"),
        (dict(planes=True), TypeError, r"^planes=True: expected an integer"),
        (dict(seed=False), TypeError, r"^seed=False: expected an integer"),
        (dict(threads=True), TypeError, r"^threads=True: expected an integer"),
        (dict(time_budget=True), TypeError, r"^time_budget=True: expected a number, got bool$"),
        (dict(resolution=(True, 6)), TypeError, r"^resolution=True: expected an integer"),
    ],
)
def test_render_names_every_argument_of_the_wrong_type(scene, kwargs, error, says):
    with pytest.raises(error, match=says):
        fogplanes.render(scene, **{**SMALL, "planes": 10, **kwargs})


def test_the_chunked_and_reference_functions_name_theirs(scene):
    with pytest.raises(TypeError, match=r"^estimator=5: expected a name"):
        fogplanes.plan_render(scene, estimator=5)
    with pytest.raises(TypeError, match=r"^pixel_center='x': expected True or False"):
        fogplanes.render_chunk(scene, (0, 16384), pixel_center="x", **CHUNKED)
    with pytest.raises(TypeError, match=r"^chunk=\(True, 16384\): expected a \(start, end\) pair"):
        fogplanes.render_chunk(scene, (True, 16384), **CHUNKED)
    with pytest.raises(TypeError, match=r"^uniform='yes': expected True or False"):
        fogplanes.reference(scene, spp=16, uniform="yes", **SMALL)
    with pytest.raises(TypeError, match=r"^spp=True: expected an integer"):
        fogplanes.reference(scene, spp=True, **SMALL)
    # Negative rows were an OverflowError that named nothing.
    for rows, error in [((-1, 3), ValueError), ((0, 2**64), ValueError), ((0.0, 3), TypeError),
                        ((True, 3), TypeError), ((0,), TypeError), ("0:3", TypeError)]:
        with pytest.raises(error, match=r"^rows="):
            fogplanes.reference_rows(scene, rows, spp=16, uniform=True, **SMALL)
        with pytest.raises(error, match=r"^rows="):
            fogplanes.reference_pilot_rows(scene, rows, spp=16, **SMALL)
    with pytest.raises(ValueError, match=r"^rows=\(0, 4294967296\): row indices must be below 2\*\*32$"):
        fogplanes.reference_rows(scene, (0, 2**32), spp=16, uniform=True, **SMALL)


def _state_with(partial, **changes):
    """The pickled state of `partial` (what __reduce__ gives) with fields changed."""
    rebuild, (state,) = partial.__reduce__()
    names = ["width", "height", "sums", "start", "end", "planes_total", "fingerprint", "hits", "seconds", "devices"]
    fields = dict(zip(names, state))
    fields.update(changes)
    return rebuild, tuple(fields[n] for n in names)


@pytest.mark.parametrize("value", [np.nan, np.inf, 1e308, -1.0])
def test_an_unpickled_partial_holding_sums_no_render_makes_is_refused(scene, value):
    p = fogplanes.render_chunk(scene, (0, 16384), **CHUNKED)
    sums = p.sums.copy()
    sums[1, 2, 1] = value
    rebuild, state = _state_with(p, sums=sums.astype("<f8").tobytes())
    # Was: unpickled, and finish_render returned an image holding NaN or infinity.
    with pytest.raises(ValueError, match=r"pixel \(x 2, y 1\) channel G is"):
        rebuild(state)
    # Through pickle itself, as a worker's result reaches the client.
    forged = pickle.dumps(p).replace(p.sums.astype("<f8").tobytes(), sums.astype("<f8").tobytes())
    with pytest.raises(ValueError, match=r"not the state of a fogplanes\.Partial"):
        pickle.loads(forged)


@pytest.mark.parametrize(
    "changes, says",
    [
        (dict(end=2**64 - 1, planes_total=2**64 - 1), "plane count"),
        (dict(hits=2**64 - 1), "hits, more than one per plane and pixel"),
        (dict(seconds=float("nan")), "seconds"),
        (dict(width=True), "expected"),
        (dict(start=1), "not a union of the render's chunks"),
        (dict(devices=[]), "0 devices named"),
        (dict(devices=["cpu\nerror: forged"]), "is not a device's name"),
        (dict(devices="cpu"), r"devices='cpu': expected a list of str, got str$"),
        # Accepted: a device no render names.
        (dict(devices=["tpu"]), "\"tpu\" is not a device's name \\(cpu, gpu, or gpu: and the adapter's name"),
    ],
)
def test_an_unpickled_partial_claiming_counts_no_render_has_is_refused(scene, changes, says):
    p = fogplanes.render_chunk(scene, (0, 16384), **CHUNKED)
    rebuild, state = _state_with(p, **changes)
    with pytest.raises(ValueError, match=says):
        rebuild(state)


def test_given_back_pilots_and_counts_are_what_the_library_makes(scene):
    args = dict(spp=64, **SMALL)
    pilot = np.concatenate([fogplanes.reference_pilot_rows(scene, (0, 6), **args)])
    counts = fogplanes.reference_counts(scene, pilot, **args)
    assert counts.min() >= 1 and counts.max() <= 64 * 64
    for value in [-1.0, np.nan, np.inf]:
        bad = pilot.copy()
        bad[2, 1, 0] = value
        # A negative standard error gave its pixel 0 samples.
        with pytest.raises(ValueError, match=r"^pilot: pixel \(x 1, y 2\) channel R is"):
            fogplanes.reference_counts(scene, bad, **args)
    # Zero samples were 0/0: NaN in the band.
    zeros = np.zeros((6, 8), dtype=np.uint32)
    with pytest.raises(ValueError, match=r"^counts: pixel \(x 0, y 0\) has 0 samples"):
        fogplanes.reference_rows(scene, (0, 3), counts=zeros, **args)
    for bad, says in [(-1, "holds -1, not a whole number"), (2.5, "holds 2.5"), (np.nan, "holds NaN")]:
        c = counts.astype(np.float64)
        c[1, 3] = bad
        with pytest.raises(ValueError, match=rf"^counts: pixel \(x 3, y 1\) {says}"):
            fogplanes.reference_rows(scene, (0, 3), counts=c, **args)
    with pytest.raises(TypeError, match=r"^counts: expected an array"):
        fogplanes.reference_rows(scene, (0, 3), counts="many", **args)


def test_counts_are_capped_as_spp_is(scene):
    """counts=[[2**32-1]] ran for over 20 minutes; now refused at once (a thread with a deadline,
    so that the old behaviour fails the test instead of hanging it)."""
    args = dict(spp=16, resolution=(1, 1))
    outcome = []

    def call():
        try:
            fogplanes.reference_rows(scene, (0, 1), counts=np.array([[2**32 - 1]], dtype=np.uint32), **args)
            outcome.append("rendered")
        except ValueError as e:
            outcome.append(str(e))

    worker = threading.Thread(target=call, daemon=True)
    worker.start()
    worker.join(timeout=30)
    assert outcome, "reference_rows(counts=2**32-1) did not return within 30 s"
    assert outcome[0].startswith("counts: pixel (x 0, y 0) has 4294967295 samples; a pixel has between 1 and 1024")
    # The cap itself is accepted.
    fogplanes.reference_rows(scene, (0, 1), counts=np.array([[1024]]), **args)


def test_a_part_numpy_wrote_still_merges(tmp_path):
    """The part reader now reads an archive from its directory at the end, entry by entry: a part
    rewritten by numpy.savez (zip64 extras in its local headers) merges to the same image."""
    exe = ROOT / "target" / "release" / "fogplanes"
    if not exe.exists():
        pytest.skip("the command line is not built")
    common = [str(SIX_LIGHTS), "--resolution", "8x6", "--planes", "20000", "-q"]
    for name, plane_range in [("a.npz", "0:16384"), ("b.npz", "16384:20000")]:
        subprocess.run([str(exe), "render", *common, "--plane-range", plane_range, "--partial", str(tmp_path / name)],
                       check=True, capture_output=True)
    with np.load(tmp_path / "a.npz") as z:
        np.savez(tmp_path / "c.npz", meta=z["meta"], sums=z["sums"])
    for first, image in [("a.npz", "ab.exr"), ("c.npz", "cb.exr")]:
        subprocess.run([str(exe), "merge", str(tmp_path / first), str(tmp_path / "b.npz"), "-o", str(tmp_path / image), "-q"],
                       check=True, capture_output=True)
    assert np.array_equal(fogplanes.load_image(tmp_path / "ab.exr"), fogplanes.load_image(tmp_path / "cb.exr"))


def test_a_scene_path_that_is_no_regular_file_is_refused(tmp_path):
    """A pipe given as a scene path held the interpreter's lock while the open waited for a
    writer: every thread froze and Ctrl-C did nothing. It is refused before it is opened (in a
    subprocess, so that a regression fails here rather than hanging the tests)."""
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    code = ("import fogplanes\n"
            f"try:\n    fogplanes.load_scene({str(fifo)!r})\nexcept ValueError as e:\n    print(e)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "not a regular file" in done.stdout and "Scene.from_toml" in done.stdout, done


@pytest.mark.parametrize(
    "image, error, says",
    [
        # Each side within the limit, the whole not: it was converted until the process was
        # killed for its memory (23 GB), the interpreter's lock held.
        (np.broadcast_to(np.float32(1), (32768, 32768, 3)), ValueError,
         r"^image: an image of 32768x32768 pixels would take about 24\.0 GiB to read; the limit is 16 GiB$"),
        # numpy dropped the imaginary part with a warning; an object array was converted.
        (np.ones((2, 3, 3), dtype=complex), TypeError, r"^image: expected an array of a real dtype, got dtype complex128$"),
        (np.ones((2, 3, 3), dtype=object), TypeError, r"^image: expected an array of a real dtype, got dtype object$"),
    ],
)
def test_an_image_argument_is_checked_before_it_is_converted(image, error, says):
    with pytest.raises(error, match=says):
        fogplanes.compare(image, np.ones((2, 3, 3), dtype=np.float32))


def test_save_image_and_load_image_refuse_a_value_that_is_no_number(tmp_path):
    """save_image wrote NaN into an EXR and load_image handed it back, unchecked."""
    image = np.ones((2, 3, 3), dtype=np.float32)
    image[1, 2, 1] = np.nan
    with pytest.raises(ValueError, match=r"pixel \(x 2, y 1\) channel G"):
        fogplanes.save_image(tmp_path / "nan.exr", image)
    assert not (tmp_path / "nan.exr").exists()
    # An EXR holding NaN, written by another program (Mitsuba 3's Bitmap).
    mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 writes the EXR holding NaN")
    mi.set_variant("scalar_rgb")
    mi.Bitmap(image).write(str(tmp_path / "other.exr"))
    with pytest.raises(ValueError, match=r"other\.exr: the image holds a value that is not a finite number: pixel \(x 2, y 1\) channel G"):
        fogplanes.load_image(tmp_path / "other.exr")


def test_the_signatures_shown_are_the_ones_taken(scene):
    """inspect.signature showed every argument of render and reference as positional (they are
    keyword-only: `render(S, "unweighted", 2048)` raised), and reference_rows's fourth as seed
    (it is counts)."""
    import inspect

    keyword_only = inspect.Parameter.KEYWORD_ONLY
    for f, positional in [(fogplanes.render, ["scene", "estimator"]), (fogplanes.reference, ["scene", "spp"]),
                          (fogplanes.reference_rows, ["scene", "rows", "spp", "counts"]),
                          (fogplanes.reference_pilot_rows, ["scene", "rows", "spp"]),
                          (fogplanes.reference_counts, ["scene", "pilot", "spp"])]:
        params = list(inspect.signature(f).parameters.values())
        assert [p.name for p in params if p.kind != keyword_only] == positional, f.__name__
    mean, _ = fogplanes.reference_rows(scene, (0, 1), 16, None, uniform=True, **SMALL)
    assert mean.shape == (1, 8, 3)
    assert inspect.signature(fogplanes.save_image).parameters["exposure"].default is None
