"""Tests of the Python module `fogplanes` (crates/python), installed by `pip install .`.

The bit-identity tests run the command line built by `cargo test --release` / `cargo build
--release` (target/release/fogplanes; FOGPLANES_CLI overrides the path) and compare its EXR
files with the arrays of the module, bit for bit.
"""

import importlib.resources
import os
import pickle
import signal
import subprocess
import sys
import textwrap
import threading
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

import fogplanes
from helpers import ROOT, SIX_LIGHTS, assert_bit_identical

BAD_SCENES = sorted((ROOT / "tests" / "bad_scenes").glob("*.toml"))
SMALL = dict(resolution=(96, 54), planes=2048)


def cli() -> Path:
    path = Path(os.environ.get("FOGPLANES_CLI", ROOT / "target" / "release" / "fogplanes"))
    if not path.is_file():
        pytest.fail(f"{path} is missing: build the command line with `cargo build --release` first")
    return path


def run_cli(*args, check=True) -> subprocess.CompletedProcess:
    result = subprocess.run([str(cli()), *map(str, args)], capture_output=True, text=True, timeout=300)
    if check and result.returncode != 0:
        raise AssertionError(f"fogplanes {' '.join(map(str, args))} failed: {result.stderr}")
    return result


def write_scene(tmp_path: Path, render_table: str, name: str = "scene") -> Path:
    """six_lights.toml with its [render] table replaced."""
    text = SIX_LIGHTS.read_text().split("[render]")[0] + "[render]\n" + textwrap.dedent(render_table)
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


# -- Bit identity with the command line ---------------------------------------------------------

CASES = [
    ({}, []),
    ({"estimator": "unweighted", "seed": 7, "spp": 2, "pixel_center": True},
     ["--estimator", "unweighted", "--seed", "7", "--spp", "2", "--pixel-center"]),
    ({"estimator": "smis-exact", "orientations": 3, "accelerator": "bvh", "threads": 1},
     ["--estimator", "smis-exact", "--orientations", "3", "--accelerator", "bvh", "--threads", "1"]),
    ({"estimator": "cmis-cosine", "kernel": "portable", "planes": 1000},
     ["--estimator", "cmis-cosine", "--kernel", "portable", "--planes", "1000"]),
    ({"estimator": "smis-cosine", "kernel": "per-hit", "accelerator": "brute-force", "planes": 300},
     ["--estimator", "smis-cosine", "--kernel", "per-hit", "--accelerator", "brute-force", "--planes", "300"]),
    ({"sampler": "independent", "planes": 2000, "seed": 3},
     ["--sampler", "independent", "--planes", "2000", "--seed", "3"]),
]


@pytest.mark.parametrize("kwargs,args", CASES, ids=[str(i) for i in range(len(CASES))])
def test_render_is_bit_identical_to_the_cli(tmp_path, kwargs, args):
    options = {**SMALL, **kwargs}
    image, stats = fogplanes.render(SIX_LIGHTS, **options, return_stats=True)
    out = tmp_path / "cli.exr"
    cli_args = ["--resolution", "96x54", "-q", "-o", out, *args]
    if "planes" not in kwargs:
        cli_args += ["--planes", SMALL["planes"]]
    printed = run_cli("render", SIX_LIGHTS, *cli_args).stdout
    assert image.shape == (54, 96, 3) and image.dtype == np.float32
    assert_bit_identical(image, fogplanes.load_image(out))
    assert_same_work(printed, stats)


def assert_same_work(printed: str, stats: dict) -> None:
    """The command line's summary line and Python's stats tell of the same resolved render:
    estimator and K, planes, rays (resolution x spp), hits and tests (everything else)."""
    work = lambda summary: summary.split(", gather")[0]  # noqa: E731 (the timings differ)
    assert work(printed.splitlines()[0]) == work(stats["summary"]), (printed, stats["summary"])


def test_scene_defaults_apply_as_on_the_command_line(tmp_path):
    # The scene's K applies only when the scene's estimator is the one rendered.
    path = write_scene(tmp_path, 'estimator = "smis-cosine"\norientations = 4\nplanes = 1500\nseed = 3\nspp = 2\n')
    scene = fogplanes.load_scene(path)
    for kwargs, args in [({}, []), ({"estimator": "smis-exact"}, ["-e", "smis-exact"]),
                         ({"estimator": "smis-cosine"}, ["-e", "smis-cosine"])]:
        out = tmp_path / "cli.exr"
        printed = run_cli("render", path, "--resolution", "64x36", "-q", "-o", out, *args).stdout
        image, stats = fogplanes.render(scene, resolution=(64, 36), return_stats=True, **kwargs)
        assert_bit_identical(image, fogplanes.load_image(out))
        assert_same_work(printed, stats)
        expected = {(): "smis-cosine-k4", ("smis-exact",): "smis-exact", ("smis-cosine",): "smis-cosine-k4"}
        assert stats["estimator"] == expected[tuple(kwargs.values())]
        assert stats["planes"] == 1500 and stats["rays"] == 2 * 64 * 36
    # A path renders as the scene it names.
    assert_bit_identical(fogplanes.render(str(path), resolution=(64, 36)), fogplanes.render(scene, resolution=(64, 36)))


def test_reference_is_bit_identical_to_the_cli(tmp_path):
    image, stderr = fogplanes.reference(SIX_LIGHTS, spp=32, resolution=(48, 27), seed=5)
    out, err = tmp_path / "ref.exr", tmp_path / "err.exr"
    run_cli("reference", SIX_LIGHTS, "--spp", 32, "--resolution", "48x27", "--seed", 5, "-q", "-o", out,
            "--stderr-image", err)
    assert_bit_identical(image, fogplanes.load_image(out))
    assert_bit_identical(stderr, fogplanes.load_image(err))
    assert np.all(stderr >= 0) and np.all(np.isfinite(image))
    uniform, _ = fogplanes.reference(SIX_LIGHTS, spp=16, resolution=(48, 27), uniform=True, pixel_center=True)
    run_cli("reference", SIX_LIGHTS, "--spp", 16, "--resolution", "48x27", "--uniform", "--pixel-center", "-q",
            "-o", out)
    assert_bit_identical(uniform, fogplanes.load_image(out))


def test_compare_matches_the_cli(tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    run_cli("render", SIX_LIGHTS, "--resolution", "64x36", "--planes", 500, "-q", "-o", a)
    run_cli("render", SIX_LIGHTS, "--resolution", "64x36", "--planes", 500, "--seed", 2, "-q", "-o", b)
    import json

    expected = json.loads(run_cli("compare", a, b, "--json").stdout)
    got = fogplanes.compare(fogplanes.load_image(a), fogplanes.load_image(b))
    assert got["smape"] == expected["smape"] and got["mse"] == expected["mse"]
    assert got["rel_mse"] == got["relmse"] == expected["rel_mse"]
    assert got["max_abs"] == expected["max_abs_error"]


def test_images_round_trip_and_read_as_other_readers_do(tmp_path):
    rng = np.random.default_rng(1)
    image = rng.random((5, 7, 3), dtype=np.float32) * 10
    fogplanes.save_image(tmp_path / "x.exr", image)
    assert_bit_identical(fogplanes.load_image(tmp_path / "x.exr"), image)
    fogplanes.save_image(tmp_path / "x.png", image, exposure=-2.0)
    assert (tmp_path / "x.png").stat().st_size > 0
    try:
        import mitsuba
    except ImportError:
        return  # the CI venv has it; elsewhere the round trip above suffices
    mitsuba.set_variant("scalar_rgb")
    other = np.array(mitsuba.Bitmap(str(tmp_path / "x.exr")), dtype=np.float32)
    assert_bit_identical(other[..., :3], image)


# -- Every estimator, every option ---------------------------------------------------------------

@pytest.mark.parametrize("estimator", fogplanes.ESTIMATORS)
def test_every_estimator_renders_finite_non_negative_images(estimator):
    image = fogplanes.render(SIX_LIGHTS, estimator, planes=512, resolution=(64, 36), seed=4)
    assert image.shape == (36, 64, 3) and image.dtype == np.float32
    assert np.all(np.isfinite(image)) and np.all(image >= 0) and image.mean() > 0


def test_threads_do_not_change_the_image():
    images = [fogplanes.render(SIX_LIGHTS, resolution=(80, 45), planes=3000, threads=t) for t in (None, 1, 2, 3)]
    for other in images[1:]:
        assert_bit_identical(images[0], other)


def test_stats():
    _, stats = fogplanes.render(SIX_LIGHTS, planes=1000, resolution=(64, 36), return_stats=True)
    assert stats["estimator"] == "smis-exact" and stats["planes"] == 1000 and stats["rays"] == 16 * 64 * 36  # 16 ray sets
    assert stats["hits"] > 0 and stats["kernel"] in fogplanes.KERNELS and stats["kernel"] != "auto"
    assert stats["seconds_total"] >= stats["seconds_gather"] >= 0
    assert stats["summary"].startswith("smis-exact: 1000 planes")


def test_names_and_version():
    assert fogplanes.ESTIMATORS == ("unweighted", "cmis-cosine", "smis-cosine", "smis-exact", "cmis-exact")
    assert fogplanes.KERNELS == ("auto", "avx512", "avx2", "portable", "per-hit")
    assert fogplanes.ACCELERATORS == ("raster", "bvh", "brute-force")
    cargo = tomllib.loads((ROOT / "Cargo.toml").read_text())
    assert fogplanes.__version__ == cargo["workspace"]["package"]["version"]
    package = importlib.resources.files("fogplanes")
    assert (package / "py.typed").is_file() and (package / "_fogplanes.pyi").is_file()
    assert "bit-identical" in fogplanes.render.__doc__


# -- Scenes --------------------------------------------------------------------------------------

def test_scene_fields_are_those_of_the_file():
    scene = fogplanes.load_scene(SIX_LIGHTS)
    desc = tomllib.loads(SIX_LIGHTS.read_text())
    assert scene.name == "six_lights"
    assert scene.resolution == tuple(desc["camera"]["resolution"]) == scene.camera.resolution
    assert scene.camera.position == tuple(desc["camera"]["position"])
    assert scene.camera.vfov_deg == pytest.approx(desc["camera"]["vfov_deg"])
    forward = np.subtract(desc["camera"]["look_at"], desc["camera"]["position"])
    assert np.allclose(scene.camera.forward, forward / np.linalg.norm(forward))
    assert scene.medium.min == tuple(desc["medium"]["min"]) and scene.medium.max == tuple(desc["medium"]["max"])
    rgb = lambda v: tuple(v) if isinstance(v, list) else (float(v),) * 3  # noqa: E731
    assert scene.medium.sigma_s == rgb(desc["medium"]["sigma_s"])
    assert scene.medium.sigma_a == rgb(desc["medium"]["sigma_a"])
    assert len(scene.lights) == len(desc["light"]) == 6
    for light, d in zip(scene.lights, desc["light"]):
        assert light.name == d["name"] and light.corner == tuple(d["corner"])
        assert np.allclose(light.edge_u, d["edge_u"], rtol=1e-12, atol=1e-12)
        assert np.allclose(light.edge_v, d["edge_v"], rtol=1e-12, atol=1e-12)
        assert light.radiance == rgb(d["radiance"])
        assert light.area == pytest.approx(np.linalg.norm(d["edge_u"]) * np.linalg.norm(d["edge_v"]))
        assert np.allclose(light.normal, np.cross(d["edge_u"], d["edge_v"]) / light.area)
    r = scene.render
    assert (r.planes, r.estimator, r.orientations, r.seed, r.spp) == (desc["render"]["planes"], "smis-exact", 2, 1, 16)
    assert (r.sampler, r.lobes) == ("sobol", 0.5) and "lobes=0.5" in repr(r)
    blocker = fogplanes.load_scene(ROOT / "media_scenes" / "two_lights_one_blocker.toml").render
    assert (blocker.sampler, blocker.lobes) == ("independent", 0.75)
    assert "six_lights" in repr(scene) and "ceiling" in repr(scene.lights[0])
    smaller = scene.with_resolution(32, 18)
    assert smaller.resolution == (32, 18) and scene.resolution == (640, 360)
    with pytest.raises(AttributeError):
        scene.name = "other"


def test_forward_scattering_fog_renders_as_on_the_command_line(tmp_path):
    """`[medium] g` reaches Python through the scene (Medium.g) and its render is the command
    line's, bit for bit."""
    forward_fog = ROOT / "media_scenes" / "forward_fog.toml"
    assert fogplanes.load_scene(forward_fog).medium.g == 0.85
    assert fogplanes.load_scene(SIX_LIGHTS).medium.g == 0.0
    image = fogplanes.render(forward_fog, resolution=(64, 40), planes=2048)
    out = tmp_path / "cli.exr"
    run_cli("render", forward_fog, "--resolution", "64x40", "--planes", "2048", "-q", "-o", out)
    assert_bit_identical(image, fogplanes.load_image(out))
    # The share of the planes along the lobe, as on the command line; another share is another
    # image (the same expectation), and so is none, the paper's planes.
    for lobes in (0.0, 0.25):
        other = fogplanes.render(forward_fog, resolution=(64, 40), planes=2048, lobes=lobes)
        run_cli("render", forward_fog, "--resolution", "64x40", "--planes", "2048", "--lobes", lobes, "-q", "-o", out)
        assert_bit_identical(other, fogplanes.load_image(out))
        assert not np.array_equal(other, image)
    assert fogplanes.plan_render(forward_fog, planes=2048, lobes=0.25)["lobes"] == 0.25
    assert fogplanes.plan_render(forward_fog, planes=2048)["lobes"] == 0.5


def test_scene_from_toml_equals_the_file():
    scene = fogplanes.Scene.from_toml(SIX_LIGHTS.read_text(), name="six_lights")
    assert scene.name == "six_lights" and len(scene.lights) == 6
    assert_bit_identical(fogplanes.render(scene, planes=500, resolution=(40, 24)),
                         fogplanes.render(SIX_LIGHTS, planes=500, resolution=(40, 24)))


# -- Errors --------------------------------------------------------------------------------------

@pytest.mark.parametrize("path", BAD_SCENES, ids=[p.stem for p in BAD_SCENES])
def test_bad_scenes_raise_value_error_with_the_cli_message(tmp_path, path):
    with pytest.raises(ValueError) as caught:
        fogplanes.load_scene(path)
    result = run_cli("render", path, "-o", tmp_path / "x.exr", check=False)
    assert result.returncode == 2
    assert result.stderr == f"error: {caught.value}\n"
    assert str(path) in str(caught.value)
    with pytest.raises(ValueError):
        fogplanes.render(path)


def test_bad_scene_text_names_the_file_and_field():
    text = SIX_LIGHTS.read_text().replace("sigma_a = 0.02", "sigma_a = -1.0")
    assert text != SIX_LIGHTS.read_text()
    with pytest.raises(ValueError, match=r"^fog\.toml: medium\.sigma_a: must be finite and non-negative"):
        fogplanes.Scene.from_toml(text, file="fog.toml")
    with pytest.raises(ValueError, match=r"^<string>:1:\d+: TOML syntax"):
        fogplanes.Scene.from_toml("[camera")
    with pytest.raises(ValueError, match="light"):
        fogplanes.Scene.from_toml(SIX_LIGHTS.read_text().split("[[light]]")[0])


def test_files_that_cannot_be_opened_raise_os_errors(tmp_path):
    missing = tmp_path / "missing.toml"
    for call in (fogplanes.load_scene, fogplanes.render, fogplanes.reference, fogplanes.load_image):
        with pytest.raises(FileNotFoundError, match="missing.toml"):
            call(missing)
    with pytest.raises(IsADirectoryError):
        fogplanes.load_scene(tmp_path)
    with pytest.raises(ValueError, match="cannot read as an EXR image"):
        fogplanes.load_image(SIX_LIGHTS)
    # An output the file system will not take: its OSError (it was a ValueError).
    with pytest.raises(FileNotFoundError, match="does not exist"):
        fogplanes.save_image(tmp_path / "no" / "x.exr", np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match=r"\.exr .* or \.png"):
        fogplanes.save_image(tmp_path / "x.jpg", np.zeros((2, 2, 3)))
    # A broadcast array claims a huge shape at no cost: refused before anything is allocated.
    with pytest.raises(ValueError, match="each side must be between"):
        fogplanes.save_image(tmp_path / "x.exr", np.broadcast_to(np.float32(0), (200000, 200000, 3)))
    with pytest.raises(ValueError, match="exposure"):
        fogplanes.save_image(tmp_path / "x.png", np.zeros((2, 2, 3)), exposure=float("nan"))
    # An EXR holds linear radiance: an exposure would be ignored without a word.
    with pytest.raises(ValueError, match=r"^exposure=1\.0: tone-maps PNG images only"):
        fogplanes.save_image(tmp_path / "x.exr", np.zeros((2, 2, 3)), exposure=1.0)
    assert not (tmp_path / "x.exr").exists()
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*.tmp"))


def words(message: str) -> tuple[str, str]:
    """(the setting's name, what is wrong) of a one-line error."""
    message = message.removesuffix("\n")
    assert "\n" not in message, message
    name, _, rest = message.partition(": ")
    return name, rest


def test_bad_options_raise_value_error_with_the_cli_message(tmp_path):
    # The same resolution in the core: the same words, the setting named as each front end's
    # caller wrote it (`--planes` on the command line, `planes=0` here, never a flag).
    cases = [
        ({"planes": 0}, ["--planes", "0"], "planes=0"),
        ({"spp": 0}, ["--spp", "0"], "spp=0"),
        ({"threads": 0}, ["--threads", "0"], "threads=0"),
        ({"resolution": (0, 10)}, ["--resolution", "0x10"], "resolution=(0, 10)"),
        ({"estimator": "unweighted", "orientations": 3}, ["-e", "unweighted", "--orientations", "3"],
         "orientations=3"),
        ({"orientations": 0}, ["--orientations", "0"], "orientations=0"),
        ({"planes": 2**27 + 1}, ["--planes", str(2**27 + 1)], f"planes={2**27 + 1}"),
        ({"resolution": (30000, 30000)}, ["--resolution", "30000x30000"], "resolution=(30000, 30000)"),
        ({"time_budget": -1}, ["--time-budget", "-1"], "time_budget=-1"),
        ({"time_budget": float("nan")}, ["--time-budget", "nan"], "time_budget=nan"),
        ({"time_budget": 1, "planes": 100}, ["--time-budget", "1", "--planes", "100"], "planes=100"),
    ]
    for kwargs, args, python_name in cases:
        with pytest.raises(ValueError) as caught:
            fogplanes.render(SIX_LIGHTS, **kwargs)
        result = run_cli("render", SIX_LIGHTS, "-q", "-o", tmp_path / "x.exr", *args, check=False)
        assert result.returncode == 2, (kwargs, result.stderr)
        assert result.stderr.startswith("error: ") and "--" not in str(caught.value), (result.stderr, caught.value)
        cli_name, cli_words = words(result.stderr.removeprefix("error: "))
        assert words(str(caught.value)) == (python_name, cli_words), kwargs
        assert cli_name == "--" + python_name.split("=")[0].replace("_", "-"), result.stderr
    assert not list(tmp_path.glob("*.exr"))


def test_a_render_on_a_time_budget(tmp_path):
    start = time.perf_counter()
    image, stats = fogplanes.render(SIX_LIGHTS, resolution=(64, 36), time_budget=0.3, return_stats=True)
    seconds = time.perf_counter() - start
    assert image.shape == (36, 64, 3) and np.all(np.isfinite(image)) and image.mean() > 0
    assert stats["plane_passes"] >= 1 and stats["planes"] >= 256
    # The ray sets made: small passes use fewer than the 16.
    assert stats["rays"] % (64 * 36) == 0 and 64 * 36 <= stats["rays"] <= 16 * 64 * 36, stats["rays"]
    assert seconds < 0.3 + 2.0, seconds  # the budget, and the set-up around it
    # A render of a plane count is one pass.
    assert fogplanes.render(SIX_LIGHTS, planes=300, resolution=(16, 9), return_stats=True)[1]["plane_passes"] == 1


def test_other_bad_arguments():
    with pytest.raises(ValueError, match=r"^estimator='nope': unknown estimator \"nope\"; expected one of unweighted"):
        fogplanes.render(SIX_LIGHTS, "nope")
    with pytest.raises(ValueError, match="^accelerator='octree': unknown accelerator"):
        fogplanes.render(SIX_LIGHTS, accelerator="octree")
    with pytest.raises(ValueError, match="^kernel='gpu': unknown kernel"):
        fogplanes.render(SIX_LIGHTS, kernel="gpu")
    for name, value in [("planes", -5), ("seed", -1), ("spp", 2**40), ("threads", 2**70), ("orientations", -2)]:
        with pytest.raises(ValueError, match=f"^{name}={value}: out of range"):
            fogplanes.render(SIX_LIGHTS, **{name: value})
    with pytest.raises(ValueError, match=r"^spp=0: samples per pixel must be between 1 and"):
        fogplanes.reference(SIX_LIGHTS, spp=0)
    with pytest.raises(ValueError, match=r"^resolution=\(0, 4\): each side"):
        fogplanes.reference(SIX_LIGHTS, resolution=(0, 4))
    with pytest.raises(ValueError, match=r"^resolution=\(0, 4\): each side"):
        fogplanes.load_scene(SIX_LIGHTS).with_resolution(0, 4)
    with pytest.raises(TypeError):
        fogplanes.render(SIX_LIGHTS, planes=1.5)
    with pytest.raises(TypeError):
        fogplanes.render(SIX_LIGHTS, resolution=(1, 2, 3))
    with pytest.raises(TypeError):
        fogplanes.render(SIX_LIGHTS, time_budget="soon")
    with pytest.raises(TypeError, match="fogplanes.Scene or the path"):
        fogplanes.render(42)
    # Keyword arguments are parsed by one parser per kind: a misspelt one is a TypeError, as in
    # any Python function, and help() still lists every keyword.
    with pytest.raises(TypeError, match="unexpected keyword argument 'plane'"):
        fogplanes.render(SIX_LIGHTS, plane=100)
    with pytest.raises(TypeError, match="unexpected keyword argument 'planes'"):
        fogplanes.reference(SIX_LIGHTS, planes=100)
    with pytest.raises(TypeError, match="unexpected keyword argument 'uniform'"):
        fogplanes.reference_counts(SIX_LIGHTS, np.zeros((360, 640, 3)), uniform=True)
    assert "time_budget=None" in fogplanes.render.__text_signature__
    assert "uniform=False" in fogplanes.reference.__text_signature__
    with pytest.raises(ValueError, match="differ in size"):
        fogplanes.compare(np.zeros((2, 3, 3)), np.zeros((3, 2, 3)))
    with pytest.raises(ValueError, match=r"shape \(height, width, 3\)"):
        fogplanes.compare(np.zeros((2, 3, 4)), np.zeros((2, 3, 4)))
    # An array of the wrong dimensions: one clear line, whatever the dtype or container.
    for image in (np.zeros((2, 3)), [[1.0, 2.0]], np.zeros(5, dtype=np.float16)):
        shape = np.shape(image)
        expected = f"image: expected an array of shape (height, width, 3), got {shape}"
        for call in (lambda: fogplanes.compare(image, image), lambda: fogplanes.save_image("x.exr", image)):
            with pytest.raises(ValueError) as caught:
                call()
            assert str(caught.value) == expected


SAVE_HUGE = """
import resource, sys
import numpy as np, fogplanes
# Far less address space than the float32 copy of the array would take (7.9 GB).
limit = 3 << 30
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
image = np.broadcast_to(np.float64(0), (32769, 20000, 3))
try:
    fogplanes.save_image(sys.argv[1], image)
except ValueError as e:
    print("ValueError:", e)
"""


def test_save_image_checks_the_shape_before_converting(tmp_path):
    # Before, the float64 array was converted to float32 first: MemoryError under a limit, and a
    # real 7.9 GB allocation without one, only to be refused for its size afterwards.
    result = subprocess.run([sys.executable, "-c", SAVE_HUGE, str(tmp_path / "x.exr")], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("ValueError: image: each side must be between 1 and 32768 pixels"), result.stdout
    assert not list(tmp_path.iterdir())


# -- compare -------------------------------------------------------------------------------------

def test_compare_known_answers_and_dtypes():
    reference = np.array([[[1.0, 0.0, 2.0], [0.5, 0.5, 0.5]]])
    image = np.array([[[3.0, 0.0, 2.0], [0.5, 1.5, 0.5]]])
    m = fogplanes.compare(image, reference)
    assert set(m) == {"smape", "mse", "rel_mse", "relmse", "max_abs"}
    assert m["smape"] == pytest.approx(1 / 6, rel=1e-12)  # 2/4, 0 (both zero), 0, 0, 1/2, 0
    assert m["mse"] == pytest.approx(5 / 6, rel=1e-12)  # 4, 0, 0, 0, 1, 0
    assert m["rel_mse"] == m["relmse"] == pytest.approx((4 / 1.01 + 1 / 0.26) / 6, rel=1e-9)
    assert m["max_abs"] == 2.0
    for dtype in (np.float16, np.float32, np.float64):
        assert fogplanes.compare(image.astype(dtype), reference.astype(dtype)) == m
    whole = np.array([[[3, 0, 2]]])  # integers are read as floats
    assert fogplanes.compare(whole, whole.astype(np.float32) + 1)["max_abs"] == 1.0
    assert fogplanes.compare(image.tolist(), reference) == m
    # Non-contiguous views are read as they look.
    wide = np.zeros((1, 4, 3))
    wide[:, ::2] = image
    assert fogplanes.compare(wide[:, ::2], reference) == m


def test_compare_of_an_image_with_itself_is_zero():
    image = fogplanes.render(SIX_LIGHTS, planes=300, resolution=(32, 18))
    assert fogplanes.compare(image, image) == dict.fromkeys(["smape", "mse", "rel_mse", "relmse", "max_abs"], 0.0)
    # An empty image has no error to measure: refused, not scored 0.
    with pytest.raises(ValueError, match="each side must be between"):
        fogplanes.compare(np.zeros((0, 0, 3)), np.zeros((0, 0, 3)))


# -- Threads and interruption --------------------------------------------------------------------

def test_the_gil_is_released_while_rendering():
    scene = fogplanes.load_scene(SIX_LIGHTS)
    started, done = threading.Event(), threading.Event()
    timing = {}

    def work():
        started.set()
        start = time.perf_counter()
        fogplanes.render(scene, planes=20480, resolution=(160, 90), spp=4)
        timing["render"] = time.perf_counter() - start
        done.set()

    worker = threading.Thread(target=work)
    worker.start()
    started.wait()
    last, largest_gap, ticks = time.perf_counter(), 0.0, 0
    while not done.is_set():
        now = time.perf_counter()
        largest_gap, last, ticks = max(largest_gap, now - last), now, ticks + 1
        time.sleep(0.001)
    worker.join()
    # Held by the render, the GIL would stop this loop for the whole render.
    assert ticks > 10 and largest_gap < max(0.1, timing["render"] / 2), (ticks, largest_gap, timing)


INTERRUPTED = """
import signal, sys, time, fogplanes
# A shell that starts this test in the background hands SIGINT down ignored, and Python then
# installs no KeyboardInterrupt handler: restore it, so the test does not depend on its parent.
signal.signal(signal.SIGINT, signal.default_int_handler)
scene = fogplanes.load_scene(sys.argv[1])
print("rendering", flush=True)
start = time.perf_counter()
try:
    fogplanes.render(scene, "smis-exact", spp=10000)  # minutes of work (10,000 ray sets)
except KeyboardInterrupt:
    print(f"KeyboardInterrupt after {time.perf_counter() - start:.2f} s", flush=True)
image = fogplanes.render(scene, planes=100, resolution=(16, 9))
print("rendered again", image.shape, flush=True)
"""


def test_ctrl_c_stops_a_render_with_keyboard_interrupt():
    process = subprocess.Popen([sys.executable, "-c", INTERRUPTED, str(SIX_LIGHTS)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout.readline().strip() == "rendering"
        time.sleep(0.5)
        sent = time.perf_counter()
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=20)
        stopped = time.perf_counter() - sent
    finally:
        process.kill()
    assert process.returncode == 0, err
    assert "KeyboardInterrupt after" in out and "rendered again (9, 16, 3)" in out, (out, err)
    assert stopped < 3.0, f"took {stopped:.2f} s to stop"


def test_hostile_files_and_non_finite_images_raise_value_error():
    corpus = ROOT / "tests" / "hostile"
    # 313 bytes claiming 32768x32768 pixels: refused before anything is allocated (it was 12.9 GB).
    with pytest.raises(ValueError, match="huge_header_32768.exr: .* it is truncated or crafted$"):
        fogplanes.load_image(corpus / "huge_header_32768.exr")
    # An image holding NaN is refused at the door (it loaded, and only the metrics refused it),
    # and no metric takes one given as an array (an all-NaN image scored SMAPE 0).
    with pytest.raises(ValueError, match=r"nan_pixel\.exr: .*pixel \(x 2, y 1\) channel G is NaN$"):
        fogplanes.load_image(corpus / "nan_pixel.exr")
    good = fogplanes.load_image(corpus / "good_4x3.exr")
    nan = good.copy()
    nan[1, 2, 1] = np.nan
    assert fogplanes.compare(good, good)["smape"] == 0.0
    with pytest.raises(ValueError, match=r"^the image holds .*: pixel \(x 2, y 1\) channel G is NaN$"):
        fogplanes.compare(nan, good)
    with pytest.raises(ValueError, match=r"^the reference holds .*: pixel \(x 0, y 0\) channel R is inf$"):
        fogplanes.compare(good, np.full_like(good, np.inf))
    # A device is no scene file (its size says nothing, and a pipe would block the interpreter):
    # refused before it is read.
    with pytest.raises(ValueError, match="/dev/zero: not a regular file"):
        fogplanes.load_scene("/dev/zero")


def test_device_gpu_renders_what_the_command_line_renders_on_the_gpu(tmp_path):
    """`device=` as `--device`: the GPU's image is the command line's with `--device gpu` bit
    for bit, and agrees with the CPU's within f32 rounding; a bad name is named. Without a
    Vulkan adapter (lavapipe: Debian's mesa-vulkan-drivers) the GPU part is SKIPPED, loudly."""
    assert fogplanes.DEVICES == ("cpu", "gpu", "auto")
    with pytest.raises(ValueError, match="device"):
        fogplanes.render(SIX_LIGHTS, resolution=(32, 18), planes=512, device="tpu")
    with pytest.raises(TypeError, match="device"):
        fogplanes.render(SIX_LIGHTS, resolution=(32, 18), planes=512, device=1)
    kwargs = dict(resolution=(48, 27), planes=2048, pixel_center=True)
    try:
        gpu, stats = fogplanes.render(SIX_LIGHTS, device="gpu", return_stats=True, **kwargs)
    except ValueError as e:
        if os.environ.get("FOGPLANES_REQUIRE_GPU") == "1":
            raise AssertionError(f"FOGPLANES_REQUIRE_GPU=1 but there is no GPU adapter: {e}") from e
        pytest.skip(f"SKIPPED LOUDLY: no GPU adapter here ({e}); install mesa-vulkan-drivers")
    assert stats["device"].startswith("gpu") and stats["seconds_device"] > 0 and stats["seconds_upload"] > 0
    assert stats["seconds_waited"] > 0
    # The gather's share of the GPU's time, where its timestamps split it (else 0).
    assert 0 <= stats["seconds_device_gather"] < stats["seconds_device"]
    # Pixel centres: one ray set, one chunk, one round of batches.
    assert stats["submissions"] == 1 and stats["gather_dispatches"] == 1
    assert stats["devices"] == [stats["device"]]
    # Every adapter listed; `gpu:N` picks one by its index: the default's is "gpu"'s image.
    adapters = fogplanes.devices()
    assert [a["index"] for a in adapters] == list(range(len(adapters)))
    assert sum(a["default"] for a in adapters) == 1 and all(a["max_binding"] > 0 for a in adapters)
    default = next(a["index"] for a in adapters if a["default"])
    assert_bit_identical(fogplanes.render(SIX_LIGHTS, device=f"gpu:{default}", **kwargs), gpu)
    with pytest.raises(ValueError, match=rf"^device='gpu:{len(adapters)}': gpu:{len(adapters)}: there (is|are) "):
        fogplanes.render(SIX_LIGHTS, device=f"gpu:{len(adapters)}", **kwargs)
    # Partials gathered on both devices: the finished image's stats name both, each once.
    chunked = dict(resolution=(16, 9), planes=16400)
    on_cpu = fogplanes.render_chunk(SIX_LIGHTS, (0, 16384), **chunked)
    on_gpu = fogplanes.render_chunk(SIX_LIGHTS, (16384, 16400), device="gpu", **chunked)
    assert on_cpu.devices == ["cpu"] and on_gpu.devices == [stats["device"]]
    both = pickle.loads(pickle.dumps(on_cpu + on_gpu))
    assert both.devices == ["cpu", stats["device"]]
    _, merged = fogplanes.finish_render(SIX_LIGHTS, both, return_stats=True, **chunked)
    assert merged["devices"] == ["cpu", stats["device"]]
    cpu = fogplanes.render(SIX_LIGHTS, **kwargs)
    fog = cpu.max(axis=2) < 1  # the pixels that see no light directly
    # Within f32 rounding but at grazing hits: the GPU makes its own rays, within f32 rounding
    # of the CPU's, and a hit on a plane's edge to rounding may fall on the other side there
    # (docs/gpu.md; tests/gpu.rs counts them). Such a pixel moves by a hit's share of it.
    moved = np.linalg.norm(gpu[fog] - cpu[fog], axis=1) > 1e-4 * np.linalg.norm(cpu[fog], axis=1)
    assert moved.sum() <= 2, f"{moved.sum()} of {moved.size} pixels beyond f32 rounding"
    exe = ROOT / "target" / "release" / "fogplanes"
    if not exe.exists():
        pytest.skip(f"SKIPPED: {exe} is not built (cargo build --release)")
    out = tmp_path / "gpu.exr"
    subprocess.run([exe, "render", SIX_LIGHTS, "--resolution", "48x27", "--planes", "2048", "--pixel-center",
                    "--device", "gpu", "-o", out, "--quiet"], check=True, capture_output=True)
    assert_bit_identical(fogplanes.load_image(out), gpu)
