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
        # A str of no valid Unicode (a lone surrogate) said so: "expected a name (a str), got str".
        (dict(estimator="\ud800"), ValueError, r"^estimator: not valid Unicode text"),
        (dict(device="\ud800"), ValueError, r"^device: not valid Unicode text"),
        (dict(sampler=1.5), TypeError, r"^sampler=1.5: expected a name"),
        (dict(pixel_center="x"), TypeError, r"^pixel_center='x': expected True or False, got str$"),
        (dict(return_stats=1), TypeError, r"^return_stats=1: expected True or False, got int$"),
        # Bools were counts: spp=True rendered one ray set.
        (dict(spp=True), TypeError, r"^spp=True: expected an integer, got bool$"),
        (dict(planes=True), TypeError, r"^planes=True: expected an integer"),
        (dict(seed=False), TypeError, r"^seed=False: expected an integer"),
        (dict(threads=True), TypeError, r"^threads=True: expected an integer"),
        (dict(time_budget=True), TypeError, r"^time_budget=True: expected a number, got bool$"),
        (dict(lobes="half"), TypeError, r"^lobes='half': expected a number, got str$"),
        (dict(lobes=True), TypeError, r"^lobes=True: expected a number, got bool$"),
        (dict(lobes=1.5), ValueError, r"^lobes=1.5: the share of the planes swept along the lobe must be between 0 and 1, got 1.5$"),
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
        # Of the right kind but out of its place's range, or no valid Unicode: said so (it said
        # "width=-1: expected int, got int").
        (dict(width=-1), r"width=-1: out of range$"),
        (dict(hits=-1), r"hits=-1: out of range$"),
        (dict(end=2**64), r"end=18446744073709551616: out of range$"),
        (dict(fingerprint="\ud800"), r"fingerprint='\\ud800': not valid Unicode text$"),
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
    # Another number of dimensions is a wrong shape (it was a TypeError, "got ndarray"); bools
    # are no counts (True counted one sample).
    for shaped, shape in [(counts[..., None], r"\(6, 8, 1\)"), (counts[0, 0], r"\(\)")]:
        with pytest.raises(ValueError, match=rf"^counts: expected shape \(6, 8\), got {shape}$"):
            fogplanes.reference_rows(scene, (0, 3), counts=shaped, **args)
    with pytest.raises(TypeError, match=r"^counts: expected whole numbers of samples, got an array of bools$"):
        fogplanes.reference_rows(scene, (0, 3), counts=counts > 0, **args)


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


def test_a_path_that_is_no_regular_file_is_refused(tmp_path):
    """A pipe given as a scene or image path held the interpreter's lock while the open waited
    for a writer: every thread froze and Ctrl-C did nothing (load_image: the library refused the
    pipe, and the choice of the exception opened it). It is refused before it is opened (in a
    subprocess, so that a regression fails here rather than hanging the tests)."""
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    for call, says in [("load_scene", "Scene.from_toml"), ("load_image", "not a regular file")]:
        code = ("import fogplanes\n"
                f"try:\n    fogplanes.{call}({str(fifo)!r})\nexcept ValueError as e:\n    print(e)\n")
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
        assert "not a regular file" in done.stdout and says in done.stdout, (call, done)


def test_an_output_the_file_system_refuses_is_its_oserror(tmp_path):
    """save_image's path, where the file system will not take it: the OSError of why, as a file
    that cannot be opened is (it was a ValueError); a name of no image format stays one."""
    image = np.zeros((4, 4, 3), np.float32)
    (tmp_path / "file").write_text("x")
    (tmp_path / "dir.exr").mkdir()
    for path, error, says in [
        (tmp_path / "missing" / "x.exr", FileNotFoundError, "the output directory .* does not exist"),
        (tmp_path / "dir.exr", IsADirectoryError, "is a directory"),
        (tmp_path / "file" / "x.exr", NotADirectoryError, "file"),
        # The name's format is checked first, whatever the directory: the caller's ValueError.
        (tmp_path / "x.jpg", ValueError, r"must end in \.exr"),
        (tmp_path / "missing" / "x.jpg", ValueError, r"must end in \.exr"),
        (tmp_path, ValueError, r"must end in \.exr"),
    ]:
        with pytest.raises(error, match=says) as raised:
            fogplanes.save_image(path, image)
        assert type(raised.value) is error, (path, raised.value)


def test_a_forged_scene_pickle_is_named(scene):
    """A scene's pickle rebuilt from forged parts: every part of its type, else a ValueError
    naming it (a resolution of -1 or 2**32 was pyo3's OverflowError naming nothing, (True,
    True) a 1x1 scene, a lone surrogate a UnicodeEncodeError)."""
    rebuild, (text, name, file, resolution) = scene.__reduce__()
    assert rebuild(text, name, file, resolution).resolution == scene.resolution
    for forged in [(-1, 1), (2**32, 1), (4.0, 4), (True, True), (4,), None]:
        with pytest.raises(ValueError, match=r"^not the state of a fogplanes\.Scene: resolution="):
            rebuild(text, name, file, forged)
    with pytest.raises(ValueError, match="each side must be between 1 and"):
        rebuild(text, name, file, (0, 4))
    with pytest.raises(ValueError, match=r"^not the state of a fogplanes\.Scene: text: not valid Unicode"):
        rebuild(text + "#\ud800", name, file, resolution)
    with pytest.raises(ValueError, match=r"^not the state of a fogplanes\.Scene: name=5: expected a str"):
        rebuild(text, 5, file, resolution)


def test_scene_text_that_is_no_valid_unicode_is_said_so(scene):
    """A str holding a lone surrogate (which Python allows) is no text: a ValueError saying so,
    where it was "text: expected the scene's TOML text (a str), got str"."""
    for kwargs, arg in [(dict(), "text"), (dict(name="\ud800"), "name"), (dict(file="\ud800"), "file")]:
        text = scene.source + ("#\ud800" if arg == "text" else "")
        with pytest.raises(ValueError, match=rf"^{arg}: not valid Unicode text"):
            fogplanes.Scene.from_toml(text, **kwargs)


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


class _FsPath:
    """An os.PathLike whose __fspath__ gives `value` (str, bytes, or neither)."""

    def __init__(self, value):
        self.value = value

    def __fspath__(self):
        return self.value


def test_a_path_is_what_open_takes_and_anything_else_is_named(scene, tmp_path):
    """A path given as bytes was "'bytes' object is not an instance of 'str'", and an int "expected
    str, bytes or os.PathLike object, not int" (naming bytes, which it refused): neither named
    the argument. Bytes are now decoded as os.fsdecode decodes them, as open() takes them."""
    raw = os.fsencode(SIX_LIGHTS)
    assert fogplanes.load_scene(raw).source == scene.source
    assert fogplanes.load_scene(_FsPath(raw)).source == scene.source
    assert fogplanes.render(raw, planes=10, **SMALL).shape == (6, 8, 3)
    image = fogplanes.render(scene, planes=10, **SMALL)
    fogplanes.save_image(os.fsencode(tmp_path / "a.exr"), image)
    assert np.array_equal(fogplanes.load_image(os.fsencode(tmp_path / "a.exr")), image)
    if os.name == "posix":  # a name that is no UTF-8: its bytes, as the file system holds them
        odd = os.path.join(os.fsencode(tmp_path), b"scene-\xff.toml")
        with open(odd, "w") as f:
            f.write(scene.source)
        assert fogplanes.load_scene(odd).source == scene.source
        assert fogplanes.load_scene(os.fsdecode(odd)).source == scene.source
    for call in (lambda v: fogplanes.load_scene(v), lambda v: fogplanes.load_image(v),
                 lambda v: fogplanes.save_image(v, image)):
        with pytest.raises(TypeError, match=r"^path: expected a path \(str, bytes or os\.PathLike\), got int$"):
            call(5)
        with pytest.raises(TypeError, match=r"^path: expected _FsPath\.__fspath__\(\) to return str or bytes, "
                                            r"not int$"):
            call(_FsPath(5))
        # Python's open() refuses it too ("embedded null byte"); it was an OSError.
        with pytest.raises(ValueError, match=r"^path='a\\x00b': a path cannot hold a NUL byte$"):
            call("a\0b")
    with pytest.raises(TypeError, match=r"^scene: expected a fogplanes\.Scene or the path of a scene file "
                                        r"\(str, bytes or os\.PathLike\), got bytearray$"):
        fogplanes.render(bytearray(raw))


def test_merge_partials_and_the_partial_functions_name_their_arguments(scene):
    """merge_partials(5) was "'int' object is not iterable", combine(p, 5) and finish_render(S, 5)
    "'int' object is not an instance of 'Partial'", none naming the argument."""
    p = fogplanes.render_chunk(scene, (0, 16384), **CHUNKED)
    q = fogplanes.render_chunk(scene, (16384, 20000), **CHUNKED)
    for parts, says in [(5, "got int"), (p, "got Partial"), ("ab", "got str"), (None, "got NoneType")]:
        with pytest.raises(TypeError, match=rf"^parts: expected a list of fogplanes\.Partial, {says}$"):
            fogplanes.merge_partials(parts)
    with pytest.raises(TypeError, match=r"^parts\[1\]: expected a fogplanes\.Partial, got int$"):
        fogplanes.merge_partials([p, 5])
    with pytest.raises(ValueError, match=r"^parts: no partial renders to merge$"):
        fogplanes.merge_partials([])
    with pytest.raises(ValueError, match=r"^parts: planes 16384:20000 are missing$"):
        fogplanes.merge_partials((p,))
    whole = fogplanes.merge_partials(x for x in (q, p))  # any iterable
    assert (whole.start, whole.end) == (0, 20000)
    with pytest.raises(TypeError, match=r"^a: expected a fogplanes\.Partial, got int$"):
        fogplanes.combine(5, q)
    with pytest.raises(TypeError, match=r"^b: expected a fogplanes\.Partial, got NoneType$"):
        fogplanes.combine(p, None)
    with pytest.raises(TypeError, match=r"^unsupported operand type\(s\) for \+: 'fogplanes\.Partial' and 'int'$"):
        p + 5
    with pytest.raises(TypeError, match=r"^partial: expected a fogplanes\.Partial, got int$"):
        fogplanes.finish_render(scene, 5, **CHUNKED)
    with pytest.raises(TypeError, match=r"^return_stats=1: expected True or False, got int$"):
        fogplanes.finish_render(scene, whole, return_stats=1, **CHUNKED)


@pytest.mark.parametrize(
    "call, error, says",
    [
        # Was "planes: expected an integer (TypeError: 'float' object cannot be interpreted as an
        # integer)": the argument, not its value nor its type.
        (lambda s: fogplanes.render(s, planes=2048.0, **SMALL), TypeError,
         r"^planes=2048\.0: expected an integer, got float$"),
        (lambda s: fogplanes.render(s, seed=1.0, **SMALL), TypeError, r"^seed=1\.0: expected an integer, got float$"),
        (lambda s: fogplanes.render(s, spp="4", **SMALL), TypeError, r"^spp='4': expected an integer, got str$"),
        (lambda s: fogplanes.render(s, orientations=2.0, **SMALL), TypeError,
         r"^orientations=2\.0: expected an integer, got float$"),
        (lambda s: fogplanes.render(s, threads=np.float64(2), **SMALL), TypeError,
         r"^threads=np\.float64\(2\.0\): expected an integer, got float64$"),
        (lambda s: fogplanes.render(s, resolution=(8.0, 6)), TypeError,
         r"^resolution=8\.0: expected an integer, got float$"),
        (lambda s: fogplanes.render(s, resolution=8), TypeError,
         r"^resolution=8: expected \(width, height\), got int$"),
        (lambda s: fogplanes.render(s, time_budget="soon", **SMALL), TypeError,
         r"^time_budget='soon': expected a number, got str$"),
        (lambda s: fogplanes.render(s, time_budget=10**400, **SMALL), ValueError,
         r"^time_budget=1{1}0{76}\.\.\.: out of range$"),
        (lambda s: fogplanes.plan_render(s, planes=2048.0), TypeError,
         r"^planes=2048\.0: expected an integer, got float$"),
        (lambda s: fogplanes.render_chunk(s, (0, 16384), spp=1.5, **CHUNKED), TypeError,
         r"^spp=1\.5: expected an integer"),
        (lambda s: fogplanes.reference(s, 16.0, **SMALL), TypeError, r"^spp=16\.0: expected an integer, got float$"),
        (lambda s: fogplanes.reference(s, 16, seed=1.0, **SMALL), TypeError,
         r"^seed=1\.0: expected an integer, got float$"),
        (lambda s: fogplanes.reference_pilot_rows(s, (0, 1), 16.0, **SMALL), TypeError,
         r"^spp=16\.0: expected an integer"),
        # Were "chunks: expected an integer, got float" and "block: out of range, got -1".
        (lambda s: fogplanes.merge_plan(2.0, 1), TypeError, r"^chunks=2\.0: expected an integer, got float$"),
        (lambda s: fogplanes.merge_plan(4, -1), ValueError,
         r"^block=-1: out of range \(a non-negative integer below 2\*\*64\)$"),
        (lambda s: s.with_resolution(8.0, 6), TypeError, r"^width=8\.0: expected an integer, got float$"),
        (lambda s: s.with_resolution(8, "6"), TypeError, r"^height='6': expected an integer, got str$"),
        (lambda s: fogplanes.save_image("never.png", np.ones((2, 3, 3)), exposure="+1"), TypeError,
         r"^exposure='\+1': expected a number, got str$"),
        # Were "'bytes' object is not an instance of 'str'" and "'int' object ...".
        (lambda s: fogplanes.Scene.from_toml(s.source.encode()), TypeError,
         r"^text: expected the scene's TOML text \(a str\), got bytes$"),
        (lambda s: fogplanes.Scene.from_toml(s.source, name=5), TypeError, r"^name=5: expected a str, got int$"),
        (lambda s: fogplanes.Scene.from_toml(s.source, file=b"x.toml"), TypeError,
         r"^file=b'x\.toml': expected a str, got bytes$"),
    ],
)
def test_a_count_or_number_of_the_wrong_type_is_named_with_its_value(scene, call, error, says):
    with pytest.raises(error, match=says):
        call(scene)


@pytest.mark.parametrize(
    "call, error, says",
    [
        # Were ValueError "expected an array of shape (height, width, 3), got ()": a number or a
        # str is no array of the wrong shape.
        (lambda s, im: fogplanes.compare(5, im), TypeError, r"^image: expected an array, got int$"),
        (lambda s, im: fogplanes.compare(im, "ref.exr"), TypeError, r"^reference: expected an array, got str$"),
        (lambda s, im: fogplanes.compare(None, im), TypeError, r"^image: expected an array, got NoneType$"),
        (lambda s, im: fogplanes.save_image("never.exr", 5), TypeError, r"^image: expected an array, got int$"),
        (lambda s, im: fogplanes.reference_counts(s, 5, spp=16, **SMALL), TypeError,
         r"^pilot: expected an array, got int$"),
        # Something with a shape numpy cannot read was numpy's "float() argument must be ...".
        (lambda s, im: fogplanes.compare(fogplanes.render_chunk(s, (0, 16384), **CHUNKED), im), TypeError,
         r"^image: expected an array, got Partial$"),
        # A ragged list was numpy's ValueError, naming nothing.
        (lambda s, im: fogplanes.compare([[1.0, 2.0], [3.0]], im), ValueError,
         r"^image: setting an array element with a sequence"),
    ],
)
def test_an_image_argument_that_is_no_array_is_named(scene, call, error, says):
    with pytest.raises(error, match=says):
        call(scene, np.ones((6, 8, 3), dtype=np.float32))


def test_an_image_value_beyond_float32_is_named_as_given(tmp_path):
    """A float64 image's finite value beyond float32's range is named as given, before the
    conversion made it an infinity (with numpy's RuntimeWarning) refused as one; an exposure
    beyond it says why it reads as infinite."""
    import warnings
    image = np.zeros((4, 4, 3))
    image[1, 2, 1] = 1e300
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        save = lambda: fogplanes.save_image(tmp_path / "never.exr", image)  # noqa: E731
        for call in (save, lambda: fogplanes.compare(image, image * 0)):
            with pytest.raises(ValueError, match=r"^image: pixel \(x 2, y 1\) channel G is 1e300, beyond float32's range"):
                call()
    with pytest.raises(ValueError, match=r"got inf \(an infinity, or a number beyond about 3\.4e38\)$"):
        fogplanes.save_image(tmp_path / "never.png", image * 0, exposure=1e308)
    # FLT_MAX as written (3.40282347e38) rounds to a finite float32: taken.
    fogplanes.save_image(tmp_path / "max.exr", np.full((2, 2, 3), 3.40282347e38))
    assert not (tmp_path / "never.exr").exists()
