"""Cluster task planning and animation frame numbering (no Dask needed)."""

import numpy as np
import pytest

from drt.farm import plan
from drt.farm.plan import plan_frame
from drt.frames import frame_path, parse_frames


@pytest.mark.parametrize("bounds,offset,count,min_tasks", [
    ((0, 0, 96, 96), 0, 16, 4),
    ((0, 0, 1920, 1080), 0, 128, 16),
    ((0, 0, 64, 64), 0, 100_000, 8),   # small image, many samples: sample ranges too
    ((10, 5, 37, 20), 3, 9, 2),        # a border region and a sample sub-range
    ((0, 0, 1, 1), 0, 1, 8),
])
def test_tasks_cover_every_pixel_sample_exactly_once(bounds, offset, count, min_tasks):
    tasks = plan_frame(bounds, offset, count, min_tasks=min_tasks)
    x0, y0, x1, y1 = bounds
    hits = np.zeros((y1, x1), dtype=np.int64)
    for t in tasks:
        tx0, ty0, tx1, ty1 = t.tile
        assert x0 <= tx0 < tx1 <= x1 and y0 <= ty0 < ty1 <= y1
        assert offset <= t.sample_offset and t.sample_offset + t.sample_count <= offset + count
        hits[ty0:ty1, tx0:tx1] += t.sample_count
    assert (hits[y0:y1, x0:x1] == count).all() and hits.sum() == (x1 - x0) * (y1 - y0) * count
    assert len(tasks) == len(set(tasks))


def test_task_size_follows_the_time_target():
    tasks = plan_frame((0, 0, 1920, 1080), 0, 128, min_tasks=4)
    target = plan.TASK_SECONDS * plan.PATHS_PER_SECOND
    assert max(t.paths for t in tasks) <= plan.MAX_TILE_TASK_FACTOR * target
    assert all(t.sample_count == 128 for t in tasks)  # tiles only: bit-identical to local
    assert min((t.tile[2] - t.tile[0]) * (t.tile[3] - t.tile[1]) for t in tasks) >= plan.MIN_TILE_PIXELS // 2
    # many samples on a small image: cut into sample ranges, each a few seconds' work
    tasks = plan_frame((0, 0, 64, 64), 0, 100_000)
    assert len({t.sample_offset for t in tasks}) > 1
    assert max(t.paths for t in tasks) <= 1.1 * target


def test_at_least_min_tasks_unless_tiny_and_never_sample_ranges_when_adaptive():
    assert len(plan_frame((0, 0, 256, 256), 0, 4, min_tasks=8)) >= 8
    assert len(plan_frame((0, 0, 8, 8), 0, 4, min_tasks=8)) == 1  # 256 paths: one task
    tasks = plan_frame((0, 0, 64, 64), 0, 100_000, split_samples=False)
    assert all((t.sample_offset, t.sample_count) == (0, 100_000) for t in tasks)


def test_frame_numbering_like_blender():
    assert frame_path("out/OUT_####.exr", 7) == "out/OUT_0007.exr"
    assert frame_path("OUT_##.exr", 123) == "OUT_123.exr"  # more digits than #: not cut
    assert frame_path("a#/b_###_x##.exr", 5) == "a#/b_###_x05.exr"  # last run of the file name
    assert frame_path("render/OUT.exr", 12) == "render/OUT0012.exr"  # no #: before the extension
    assert frame_path("OUT", 3) == "OUT0003"


def test_frame_ranges():
    assert parse_frames("1-4") == [1, 2, 3, 4]
    assert parse_frames("7") == [7]
    assert parse_frames("1,5, 10-12,5") == [1, 5, 10, 11, 12]
    for bad in ("", "a-b", "5-1", "1-", "-3", "1-2000000"):
        with pytest.raises(ValueError):
            parse_frames(bad)


def test_tiles_rendered_apart_are_the_whole_frame_bit_for_bit():
    """render(tile=...): each pixel gets the whole-frame render's samples in the same order,
    with or without adaptive sampling, so cluster tiles need no tolerance."""
    import os
    from dataclasses import replace

    from drt.render import prepare, render
    from drt.scene_file import load_scene

    scene = load_scene(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "blend_scenes", "cornell_box.npz"))
    for adaptive in (0.0, 0.05):
        scene.render = replace(scene.render, width=40, height=30, adaptive_threshold=adaptive,
                               adaptive_min_samples=4)
        ctx = prepare(scene)
        whole = render(scene, spp=16, threads=2, context=ctx)
        for tile in ((0, 0, 17, 30), (17, 0, 40, 13), (17, 13, 40, 30)):
            part = render(scene, spp=16, threads=1, context=ctx, tile=tile)
            x0, y0, x1, y1 = tile
            assert part.meta["tile"] == list(tile) and (part.width, part.height) == (x1 - x0, y1 - y0)
            for name, ch in (("sum_rgba", 4), ("count", 1), ("min_depth", 1), ("sum_lum2", 1)):
                a = getattr(whole, name).reshape(30, 40, ch)[y0:y1, x0:x1]
                assert np.array_equal(a, getattr(part, name).reshape(y1 - y0, x1 - x0, ch)), (adaptive, name)
        if adaptive:
            assert whole.count.min() < whole.count.max()  # some pixels did stop early
