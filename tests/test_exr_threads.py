"""drt.exr compresses on every core: OpenEXR's Python binding starts with no threads, and the
file a render writes must not depend on how many it uses."""

import numpy as np
import OpenEXR

from drt.exr import film_from_exr, read_exr, use_threads, write_exr
from drt.film import Film


def _film():
    rng = np.random.default_rng(7)
    f = Film(97, 61)  # (not a multiple of OpenEXR's 16-line ZIP blocks)
    f.sum_rgba[:] = rng.random(f.sum_rgba.shape) * 3
    f.sum_normal[:] = rng.normal(size=f.sum_normal.shape)
    f.count[:] = rng.integers(0, 5, f.count.shape)
    return f


def test_write_exr_uses_the_threads_it_is_given_and_writes_the_same_file_on_any_count(tmp_path):
    film = _film()
    write_exr(tmp_path / "one.exr", film, threads=1)
    assert OpenEXR.global_thread_count() == 1
    write_exr(tmp_path / "three.exr", film, threads=3)
    assert OpenEXR.global_thread_count() == 3
    assert (tmp_path / "one.exr").read_bytes() == (tmp_path / "three.exr").read_bytes()
    ch, _ = read_exr(tmp_path / "three.exr")
    np.testing.assert_array_equal(ch["R"], film.combined[..., 0])
    np.testing.assert_array_equal(film_from_exr(tmp_path / "one.exr").count, film.count)
    use_threads()
    assert OpenEXR.global_thread_count() >= 1
