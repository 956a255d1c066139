"""The film's passes as images: the compiled per-pass kernels give, bit for bit, what NumPy's
float64 formulas give (the definitions they replaced), on films with empty pixels, zero normals
and negative sums."""

import numpy as np

from drt.film import Film, luminance


def _film(w=37, h=23, seed=5):
    rng = np.random.default_rng(seed)
    f = Film(w, h)
    n = w * h
    f.count[:] = rng.integers(0, 6, n)
    f.sum_rgba[:] = rng.normal(size=(n, 4)) * f.count[:, None] * 3.0
    f.sum_normal[:] = rng.normal(size=(n, 3)) * (rng.random((n, 1)) > 0.2)
    f.sum_albedo[:] = rng.random((n, 3)) * f.count[:, None]
    f.sum_lum2[:] = rng.random(n) * 10.0 * f.count
    return f


def _mean(f, s):
    return s / np.maximum(f.count, 1).reshape((-1,) + (1,) * (s.ndim - 1))


def _image(f, flat):
    return flat.reshape((f.height, f.width) + flat.shape[1:]).astype(np.float32)


def test_combined_albedo_normal_and_variance_are_numpys_float64_formulas_bit_for_bit():
    f = _film()
    rgba = _mean(f, f.sum_rgba)
    rgba[:, 3] = np.clip(rgba[:, 3], 0.0, 1.0)
    nrm = _mean(f, f.sum_normal)
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    n = f.count.astype(np.float64)
    mean = luminance(_mean(f, f.sum_rgba)[:, :3])
    var = np.maximum(f.sum_lum2 / np.maximum(n, 1) - mean**2, 0.0) * n / np.maximum(n - 1, 1) / np.maximum(n, 1)
    expected = {
        "combined": _image(f, rgba),
        "albedo": _image(f, _mean(f, f.sum_albedo)),
        "normal": _image(f, np.where(length > 0, nrm / np.where(length > 0, length, 1), 0.0)),
        "variance": _image(f, var),
    }
    for name, want in expected.items():
        got = getattr(f, name)
        assert got.dtype == np.float32 and got.shape == want.shape, name
        np.testing.assert_array_equal(got, want, err_msg=name)
    assert np.any(f.combined[..., 3] == 1.0) and np.any(f.combined[..., 3] == 0.0)  # (the clamp ran)
    assert np.any(np.all(f.normal == 0.0, axis=-1))  # (pixels without a normal stay 0)


def test_a_merged_films_images_are_its_parts_sums():
    """Films merged from parts (float64 sums that are not views of one block) resolve alike."""
    a, b = _film(seed=1), _film(seed=2)
    whole = Film(a.width, a.height)
    whole.merge(a)
    whole.merge(b)
    c = whole.count
    np.testing.assert_array_equal(whole.albedo.reshape(-1, 3),
                                  ((a.sum_albedo + b.sum_albedo) / np.maximum(c, 1)[:, None]).astype(np.float32))
