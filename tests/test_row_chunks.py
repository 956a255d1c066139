"""Row-wise preparation kernels over chunks of rows on threads (drt.kernels.row_chunks): the same
bytes as one call, results in row order, the render's thread limit honoured."""

from __future__ import annotations

import threading

import numpy as np

from drt.kernels import kernel
from drt.kernels import row_chunks
from drt.kernels.row_chunks import over_rows, preparation_threads


@kernel
def _scaled_gather(table, index, out):
    """out[k] = 2·table[index[k]]; returns the number of rows done."""
    for k in range(index.shape[0]):
        out[k] = 2.0 * table[index[k]]
    return index.shape[0]


def test_chunks_give_the_bytes_of_one_call_and_results_in_row_order(monkeypatch):
    monkeypatch.setattr(row_chunks, "MIN_ROWS_PER_THREAD", 1000)
    rng = np.random.default_rng(5)
    table = rng.normal(size=500)
    index = rng.integers(0, 500, 10_007).astype(np.int64)
    whole = np.empty(len(index))
    with preparation_threads(1):
        assert over_rows(_scaled_gather, (table, index, whole), sliced=(1, 2)) == [10_007]
    for threads in (2, 3, 7):
        out = np.full(len(index), np.nan)
        with preparation_threads(threads):
            done = over_rows(_scaled_gather, (table, index, out), sliced=(1, 2))
        assert len(done) == threads and sum(done) == len(index)
        assert max(done) - min(done) <= 1  # near-equal shares
        assert np.array_equal(out, whole)
    # too few rows for a second thread: one call on the calling thread
    with preparation_threads(4):
        assert over_rows(_scaled_gather, (table, index[:1500], out[:1500]), sliced=(1, 2)) == [1500]


def test_the_limit_holds_only_inside_its_block_and_only_on_its_thread():
    seen = {}
    with preparation_threads(1):
        seen["inside"] = row_chunks._THREADS.get()
        t = threading.Thread(target=lambda: seen.__setitem__("other thread", row_chunks._THREADS.get()))
        t.start()
        t.join()
    seen["after"] = row_chunks._THREADS.get()
    assert seen == {"inside": 1, "other thread": None, "after": None}
