"""F12 and ``blender -b … -E DRT`` on a Dask cluster (``scene.drt.cluster_address``).

The depsgraph is exported here, as for a local render; the exporter's plain ``(header,
arrays)`` go to the workers (no DRT class is pickled: the bundled core's module names are not
importable on a worker), tasks come back as tiles that are shown as they arrive, and Esc
cancels the cluster's tasks. Cluster problems (unreachable scheduler, no workers, time-outs)
raise the core's ``FarmError``, which the engine turns into an error report (exit 1 in
``blender -b``). Denoising, when enabled, runs here on the merged frame. See docs/farm.md.
"""

import time

import bpy

from . import compat

DRAW_SECONDS = 0.25  # at most this often the image is redrawn as tiles arrive


def cluster_address(scene) -> str:
    return scene.drt.cluster_address.strip()


def _file(path: str) -> str | None:
    return bpy.path.abspath(path) if path.strip() else None


def connect(engine, scene):
    """A Dask client of the scene's scheduler (FarmError, reported by the engine, otherwise)."""
    farm = compat.core_module("farm.client")
    d = scene.drt
    address = farm.check_address(cluster_address(scene))
    sec = farm.security(address, _file(d.cluster_tls_ca_file), _file(d.cluster_tls_cert), _file(d.cluster_tls_key))
    engine.update_stats("", f"DRT | Connecting to {address}")
    return farm.connect(address, timeout=float(d.cluster_timeout), sec=sec)


def close(client, scene) -> None:
    farm = compat.core_module("farm.client")
    with farm.quiet_dask_logs():
        client.close(timeout=min(float(scene.drt.cluster_timeout), 10))


def render_on_cluster(engine, client, scene, exported, drt_scene, spp, offset, count, result, crop, wanted,
                      t_start):
    """Render the exported frame on the cluster, drawing tiles into ``result`` as they arrive;
    returns the frame's film (``film.stats``: the cluster's ``FarmStats``), partial when
    cancelled, or None when nothing finished."""
    from .engine import _format_seconds, fill_layer

    farm = compat.core_module("farm.client")
    last_draw = [0.0]
    finished = []

    def load(_frame):
        return drt_scene, (exported.header, exported.arrays)

    def preview(_frame, film):
        now = time.perf_counter()
        if now - last_draw[0] > DRAW_SECONDS:
            last_draw[0] = now
            fill_layer(result.layers[0], film, crop, wanted, cryptomatte=False)
            engine.update_result(result)

    def progress(fraction, st):
        remaining = st.seconds / fraction - st.seconds if fraction > 0 else 0.0
        engine.update_progress(fraction)
        engine.update_stats("", f"DRT | Cluster {st.workers} workers | Tasks {st.tasks_done}/{st.tasks_total} | "
                                f"Elapsed {_format_seconds(time.perf_counter() - t_start)} | "
                                f"Remaining {_format_seconds(remaining)}")

    with farm.quiet_dask_logs():
        stats = farm.render_frames(client, [scene.frame_current], load, {"spp": spp},
                                   on_frame=lambda _frame, film: finished.append(film), preview=preview,
                                   progress=progress, cancel=engine.cancel_requested,
                                   timeout=float(scene.drt.cluster_timeout), sample_offset=offset,
                                   sample_count=count)
    state = "cancelled after" if stats.cancelled else "rendered"
    engine.update_stats("", f"DRT | {state} {stats.tasks_done} tasks on {stats.workers} workers in "
                            f"{_format_seconds(time.perf_counter() - t_start)}")
    if not finished:
        return None
    finished[0].stats = stats
    return finished[0]
