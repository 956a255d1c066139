"""Render worker processes: ``python -m drt.worker`` serves batches over its stdin/stdout.

Why processes: the numpy shading code holds the GIL between operations; on big jobs two worker
processes are a few percent faster than two threads (docs/decisions.md has the figures).
Why not ``multiprocessing``: its spawn mode re-imports the caller's ``__main__`` (a script
without an ``if __name__ == "__main__"`` guard would recurse), and fork is unsafe after Embree's
task system has started. A plain subprocess running this module has neither problem.

Protocol (pickle frames on the pipes, trusted: the parent wrote them): first frame
``(scene, overrides, spp)``; then each request ``(x, row, index)`` is answered by
``(SampleBatch, rays, embree_seconds)``; ``None`` ends the worker. An exception in the worker is
answered as ``("error", message)``.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading


def _serve() -> None:
    # Ctrl-C on a terminal signals the whole process group: the parent alone decides to cancel
    # (it stops sending batches and closes us); dying here would lose the partial image
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from .render import prepare
    from .sampling.sequences import Sampler

    inp = sys.stdin.buffer
    # The frame stream gets a private copy of fd 1; fd 1 itself then points at stderr, so
    # nothing else (a print, a C library's message) can corrupt the frames.
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    scene, overrides, spp = pickle.load(inp)
    ctx = prepare(scene, **overrides)
    integ = ctx.integrator
    integ.sampler = Sampler(integ.sampler.kind, integ.s.seed, spp)
    tr = ctx.tracer
    while True:
        try:
            req = pickle.load(inp)
        except EOFError:
            return
        if req is None:
            return
        r0, e0 = tr.rays_traced, tr.embree_seconds
        try:
            batch = integ.render_batch(*req)
            reply = (batch, tr.rays_traced - r0, tr.embree_seconds - e0)
        except Exception as e:  # reported to the parent, which raises it there
            reply = ("error", f"{type(e).__name__}: {e}")
        pickle.dump(reply, out, protocol=pickle.HIGHEST_PROTOCOL)
        out.flush()


class WorkerProcess:
    """One worker subprocess; ``call`` sends a batch and waits for its result (thread-safe
    per worker only through the pool's checkout discipline)."""

    def __init__(self, scene, overrides: dict, spp: int):
        env = dict(os.environ)
        # each worker is single-threaded: the pool provides the parallelism
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env[var] = "1"
        pkg_parent = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env["PYTHONPATH"] = pkg_parent + os.pathsep + env.get("PYTHONPATH", "")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", f"{__package__}.worker"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env,
            start_new_session=True,  # out of the terminal's process group: Ctrl-C reaches the parent only
        )
        pickle.dump((scene, overrides, spp), self.proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
        self.proc.stdin.flush()

    def call(self, x, row, idx):
        pickle.dump((x, row, idx), self.proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
        self.proc.stdin.flush()
        try:
            reply = pickle.load(self.proc.stdout)
        except EOFError:
            raise RuntimeError(f"a render worker died (exit code {self.proc.wait()})") from None
        if isinstance(reply, tuple) and len(reply) == 2 and reply[0] == "error":
            raise RuntimeError(f"render worker failed: {reply[1]}")
        return reply

    def close(self):
        try:
            pickle.dump(None, self.proc.stdin)
            self.proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


class WorkerPool:
    """N worker processes; ``submit`` returns a callable that waits for the batch's result."""

    def __init__(self, scene, overrides: dict, spp: int, n: int):
        from concurrent.futures import ThreadPoolExecutor
        from queue import Queue

        self.workers = [WorkerProcess(scene, overrides, spp) for _ in range(n)]
        self.free: Queue = Queue()
        for w in self.workers:
            self.free.put(w)
        self.feeders = ThreadPoolExecutor(max_workers=n)
        self.lock = threading.Lock()
        self.rays = 0
        self.embree = 0.0

    def _run(self, x, row, idx):
        w = self.free.get()
        try:
            batch, rays, emb = w.call(x, row, idx)
        finally:
            self.free.put(w)
        with self.lock:
            self.rays += rays
            self.embree += emb
        return batch

    def submit(self, x, row, idx):
        return self.feeders.submit(self._run, x, row, idx)

    def abort(self):
        """Stop now (cancel): queued batches are dropped and busy workers killed."""
        self.feeders.shutdown(wait=False, cancel_futures=True)
        for w in self.workers:
            if w.proc.poll() is None:
                w.proc.kill()
        for w in self.workers:
            w.proc.wait()
        self.feeders.shutdown(wait=True)

    def counters(self):
        return self.rays, self.embree

    def close(self):
        self.feeders.shutdown(wait=True)
        for w in self.workers:
            w.close()


if __name__ == "__main__":
    _serve()
