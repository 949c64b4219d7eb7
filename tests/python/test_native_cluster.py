"""The native functions under fogplanes.distributed: pickled scenes, renders in chunks merged
into the render's bits, reference bands equal to the whole reference, partial files numpy reads."""

import json
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fogplanes

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "media_scenes" / "six_lights.toml"
SETTINGS = dict(planes=2 * 16384 + 500, resolution=(24, 14), seed=3)


@pytest.fixture(scope="module")
def scene():
    return fogplanes.load_scene(SCENE)


def test_a_pickled_scene_is_the_same_scene_and_renders_identically(scene):
    small = scene.with_resolution(20, 12)
    back = pickle.loads(pickle.dumps(small))
    assert back.resolution == (20, 12) and back.name == small.name and back.source == small.source
    assert back.__dask_tokenize__() == small.__dask_tokenize__()
    assert small.__dask_tokenize__() != scene.__dask_tokenize__()
    a = fogplanes.render(small, planes=3000)
    assert np.array_equal(a, fogplanes.render(back, planes=3000))


def test_the_dask_token_is_the_same_in_another_process(scene):
    code = (
        "import fogplanes, sys; "
        f"print(fogplanes.load_scene({str(SCENE)!r}).with_resolution(20, 12).__dask_tokenize__())"
    )
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    token = scene.with_resolution(20, 12).__dask_tokenize__()
    assert other.stdout.strip() == token and len(token) == 32


def test_chunks_merged_in_any_order_are_the_render_bit_for_bit(scene):
    plan = fogplanes.plan_render(scene, **SETTINGS)
    assert plan["planes"] == SETTINGS["planes"] and plan["chunk_planes"] == 16384
    assert plan["chunks"] == [(0, 16384), (16384, 32768), (32768, SETTINGS["planes"])]
    assert plan["shape"] == (14, 24, 3) and plan["estimator"] == "smis-exact"
    whole = fogplanes.render(scene, **SETTINGS)
    parts = [fogplanes.render_chunk(scene, c, threads=1, **SETTINGS) for c in plan["chunks"]]
    assert all(p.fingerprint == plan["fingerprint"] for p in parts)
    assert parts[0].sums.dtype == np.float64 and parts[0].sums.shape == (14, 24, 3)
    # Pickled partials (as Dask ships them) keep every bit.
    parts = [pickle.loads(pickle.dumps(p)) for p in parts]
    for order in ([0, 1, 2], [2, 0, 1], [1, 2, 0]):
        merged = fogplanes.merge_partials([parts[i] for i in order])
        image = fogplanes.finish_render(scene, merged, **SETTINGS)
        assert image.dtype == np.float32 and np.array_equal(image, whole)
    # The canonical tree by hand: (0 + 1) + 2.
    by_hand = fogplanes.combine(parts[0] + parts[1], parts[2])
    assert np.array_equal(fogplanes.finish_render(scene, by_hand, **SETTINGS), whole)
    image, stats = fogplanes.finish_render(scene, by_hand, return_stats=True, **SETTINGS)
    assert stats["hits"] == sum(p.hits for p in parts) > 0


def test_partials_that_do_not_make_the_render_are_refused(scene):
    plan = fogplanes.plan_render(scene, **SETTINGS)
    a, b, c = (fogplanes.render_chunk(scene, ch, **SETTINGS) for ch in plan["chunks"])
    other = fogplanes.render_chunk(scene, plan["chunks"][2], **{**SETTINGS, "seed": 4})
    with pytest.raises(ValueError, match="different renders"):
        fogplanes.merge_partials([a, b, other])
    with pytest.raises(ValueError, match="not adjacent"):
        a + c
    with pytest.raises(ValueError, match="are missing"):
        fogplanes.merge_partials([a, c])
    with pytest.raises(ValueError, match="do not cover"):
        fogplanes.finish_render(scene, a + b, **SETTINGS)
    with pytest.raises(ValueError, match="another render"):
        fogplanes.finish_render(scene, a + b + c, **{**SETTINGS, "seed": 4})
    with pytest.raises(ValueError, match="not a union of the render's chunks"):
        fogplanes.render_chunk(scene, (1, 16384), **SETTINGS)
    with pytest.raises(ValueError, match="planes"):
        fogplanes.plan_render(scene, planes=0)
    with pytest.raises(ValueError, match="time_budget"):
        fogplanes.plan_render(scene, time_budget=1.0)
    with pytest.raises(TypeError, match="unexpected keyword"):
        fogplanes.plan_render(scene, plains=10)


def test_a_bad_chunk_is_named_before_any_conversion(scene):
    for chunk, error in [((-1, 16384), ValueError), ((0, -5), ValueError), ((0, 2**64), ValueError),
                         ((0.0, 16384), TypeError), ((0,), TypeError), ("0:16384", TypeError),
                         (None, TypeError)]:
        with pytest.raises(error, match=r"^chunk="):
            fogplanes.render_chunk(scene, chunk, **SETTINGS)
    # In range but not the render's chunks: the core's error.
    with pytest.raises(ValueError, match="not a union of the render's chunks"):
        fogplanes.render_chunk(scene, (16384, 0), **SETTINGS)


def test_the_merge_plan_is_the_cores_tree_and_gives_the_render_bit_for_bit(scene):
    settings = dict(SETTINGS, planes=4 * 16384 + 7, resolution=(12, 7))  # 5 chunks, the last short
    plan = fogplanes.plan_render(scene, **settings)
    chunks = plan["chunks"]
    whole = fogplanes.render(scene, **settings)
    singles = [fogplanes.render_chunk(scene, c, threads=1, **settings) for c in chunks]
    # The plan over 7 chunks in blocks of 2, post-order: leaves (None, None), additions of
    # two earlier steps.
    assert fogplanes.merge_plan(7, 2) == [(0, 2, None, None), (2, 4, None, None), (0, 4, 0, 1),
                                         (4, 6, None, None), (6, 7, None, None), (4, 7, 3, 4),
                                         (0, 7, 2, 5)]
    for block in (1, 2, 4):
        steps = fogplanes.merge_plan(len(chunks), block)
        parts = []
        for start, end, left, right in steps:
            if left is None:
                planes = (chunks[start][0], chunks[end - 1][1])
                parts.append(fogplanes.render_chunk(scene, planes, threads=1, **settings) if end - start > 1
                             else singles[start])
            else:
                parts.append(fogplanes.combine(parts[left], parts[right]))
                assert (parts[-1].start, parts[-1].end) == (chunks[start][0], chunks[end - 1][1])
        assert np.array_equal(fogplanes.finish_render(scene, parts[-1], **settings), whole), block
    for args, error in [((0, 1), ValueError), ((8193, 1), ValueError), ((7, 3), ValueError),
                        ((7, 0), ValueError), ((-1, 1), ValueError), ((7, -2), ValueError),
                        ((7.0, 1), TypeError), ((7, True), TypeError), ((2**70, 1), ValueError)]:
        with pytest.raises(error, match="chunks|block"):
            fogplanes.merge_plan(*args)


@pytest.mark.parametrize("uniform", [True, False])
def test_reference_rows_are_the_rows_of_the_reference(scene, uniform):
    args = dict(spp=32, seed=2, resolution=(16, 10))
    mean, err = fogplanes.reference(scene, uniform=uniform, **args)
    bands = [(0, 3), (3, 4), (4, 10)]
    counts = None
    if not uniform:
        pilot = np.concatenate([fogplanes.reference_pilot_rows(scene, b, **args) for b in bands])
        counts = fogplanes.reference_counts(scene, pilot, **args)
        assert counts.dtype == np.uint32 and counts.shape == (10, 16)
        with pytest.raises(ValueError, match="counts"):
            fogplanes.reference_rows(scene, (0, 3), **args)
    rows = [fogplanes.reference_rows(scene, b, uniform=uniform, counts=counts, **args) for b in bands]
    assert np.array_equal(np.concatenate([m for m, _ in rows]), mean)
    assert np.array_equal(np.concatenate([e for _, e in rows]), err)


def test_numpy_reads_the_partial_file_of_the_command_line(tmp_path):
    exe = ROOT / "target" / "release" / "fogplanes"
    if not exe.exists():
        pytest.skip("the command line is not built")
    part = tmp_path / "part.npz"
    subprocess.run(
        [str(exe), "render", str(SCENE), "--resolution", "24x14", "--planes", "20000",
         "--plane-range", "16384:20000", "--partial", str(part), "-q"],
        check=True, capture_output=True,
    )
    with np.load(part) as z:
        assert z["sums"].shape == (14, 24, 3) and z["sums"].dtype == np.float64
        meta = json.loads(str(z["meta"]))
    assert (meta["kind"], meta["start"], meta["end"], meta["total"]) == ("render", 16384, 20000, 20000)
    scene = fogplanes.load_scene(SCENE)
    plan = fogplanes.plan_render(scene, planes=20000, resolution=(24, 14))
    assert meta["fingerprint"] == plan["fingerprint"]
    chunk = fogplanes.render_chunk(scene, (16384, 20000), planes=20000, resolution=(24, 14))
    with np.load(part) as z:
        assert np.array_equal(z["sums"], chunk.sums)
