"""`render(..., return_stderr=True)`, `target_error` and `progress=True`: the error image is
the command line's bit for bit, beside an image unchanged by it; a render to a target error says
why it stopped; progress fits where it is shown."""

import subprocess

import fogplanes
import numpy as np
import pytest

from helpers import ROOT, SIX_LIGHTS, assert_bit_identical

SMALL = dict(resolution=(48, 27), planes=8192)


def test_the_error_image_is_the_command_lines_and_leaves_the_image_alone(tmp_path):
    image, stderr, stats = fogplanes.render(SIX_LIGHTS, return_stderr=True, return_stats=True, **SMALL)
    assert_bit_identical(image, fogplanes.render(SIX_LIGHTS, **SMALL))
    assert stderr.shape == image.shape and stderr.dtype == np.float32
    assert np.all(np.isfinite(stderr)) and stderr.min() >= 0 and stderr.max() > 0
    assert 0 < stats["relative_error"] < 1 and stats["stopped_by"] is None
    # Only the error image: (image, stderr).
    pair = fogplanes.render(SIX_LIGHTS, return_stderr=True, **SMALL)
    assert isinstance(pair, tuple) and len(pair) == 2
    exe = ROOT / "target" / "release" / "fogplanes"
    if not exe.exists():
        pytest.skip(f"SKIPPED: {exe} is not built (cargo build --release)")
    out, se = tmp_path / "a.exr", tmp_path / "se.exr"
    subprocess.run([exe, "render", SIX_LIGHTS, "--resolution", "48x27", "--planes", "8192", "-o", out,
                    "--stderr-image", se, "--quiet"], check=True, capture_output=True)
    assert_bit_identical(fogplanes.load_image(se), stderr)


def test_an_error_image_needs_two_ray_sets():
    with pytest.raises(ValueError, match="two ray sets"):
        fogplanes.render(SIX_LIGHTS, return_stderr=True, pixel_center=True, **SMALL)
    with pytest.raises(ValueError, match="target_error"):
        fogplanes.render(SIX_LIGHTS, resolution=(48, 27), target_error=1.5)
    with pytest.raises(TypeError, match="return_stderr"):
        fogplanes.render(SIX_LIGHTS, return_stderr="yes", **SMALL)


def test_a_render_to_a_target_error_says_why_it_stopped():
    _, stats = fogplanes.render(SIX_LIGHTS, resolution=(48, 27), target_error=0.05, return_stats=True)
    assert stats["stopped_by"] == "target error" and stats["relative_error"] <= 0.05
    assert 0 < stats["error_floor"] < stats["relative_error"]
    _, stats = fogplanes.render(SIX_LIGHTS, resolution=(48, 27), time_budget=0.3, return_stderr=True,
                                return_stats=True)[1:]
    assert stats["stopped_by"] == "time budget" and stats["relative_error"] > stats["error_floor"]
    # Below the floor, the direct emission's error, which planes do not lower: stopped at once
    # (it ran to the plane limit).
    _, stats = fogplanes.render(SIX_LIGHTS, resolution=(48, 27), target_error=1e-6, time_budget=60,
                                return_stats=True)
    assert stats["stopped_by"] == "error floor" and stats["planes"] < 1000
    assert 1e-6 < stats["error_floor"] <= stats["relative_error"]
    assert "which planes do not lower" in stats["relative_error_text"]


def test_a_black_image_has_no_relative_error_and_stops_a_target_error_at_once(tmp_path):
    text = (ROOT / "media_scenes" / "six_lights.toml").read_text()
    black = fogplanes.Scene.from_toml(text.replace("look_at = [0.0, 2.5, 0.0]", "look_at = [0.0, 3.0, 20.0]"))
    image, _, stats = fogplanes.render(black, resolution=(32, 18), planes=4096, return_stderr=True,
                                       return_stats=True)
    assert image.max() == 0
    assert stats["relative_error"] is None and stats["error_floor"] is None
    assert stats["relative_error_text"] == "undefined (the image is black)"
    _, stats = fogplanes.render(black, resolution=(32, 18), target_error=0.01, return_stats=True)
    assert stats["stopped_by"] == "black image" and stats["planes"] < 10_000


def test_progress_writes_lines_where_stderr_is_not_a_terminal(capfd):
    fogplanes.render(SIX_LIGHTS, resolution=(48, 27), planes=40960, progress=True)
    out, err = capfd.readouterr()
    lines = err.splitlines()
    assert out == "" and "\r" not in err, err
    assert 1 <= len(lines) <= 12 and "planes" in lines[-1] and "100%" in lines[-1], err
    fogplanes.render(SIX_LIGHTS, resolution=(48, 27), planes=4096)
    assert capfd.readouterr().err == ""
