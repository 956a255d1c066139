"""Rendering on a real Dask cluster: a LocalCluster of two worker processes (one thread each),
the CLI against it, a worker killed mid-render, a dead scheduler address and TLS.

Needs ``distributed`` (the ``farm`` extra, also in ``test``).
"""

import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from drt.exr import read_exr  # noqa: E402
from drt.farm import plan  # noqa: E402
from drt.farm.client import FarmError, connect, render_frames  # noqa: E402
from drt.render import render  # noqa: E402
from drt.scene_file import load_scene  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BOX = os.path.join(REPO, "blend_scenes", "cornell_box.npz")


def small_box(w=48, h=40):
    scene = load_scene(BOX)
    scene.render = replace(scene.render, width=w, height=h)
    return scene


@pytest.fixture
def cluster(dask_cluster):
    return dask_cluster


def cluster_render(address, scene, spp, **kw):
    films = {}
    client = connect(address, timeout=20)
    try:
        stats = render_frames(client, [None], lambda f: (scene, scene), {"spp": spp},
                              on_frame=lambda f, film: films.setdefault(f, film), **kw)
    finally:
        client.close()
    return films[None], stats


def test_tiles_on_the_cluster_are_bit_identical_to_the_local_render(cluster):
    scene = small_box(64, 64)
    # (the Mist pass and the data passes travel too)
    scene.render = replace(scene.render, mist=(1.0, 5.0, 2.0), data_passes=("object_index", "position", "uv"),
                           light_passes=("emission", "environment", "ao"), cryptomatte=("object", "material"))
    film, stats = cluster_render(cluster.scheduler_address, scene, 16, task_seconds=0.01)
    assert stats.tasks_done == stats.tasks_total == 4 and stats.workers == 2
    local = render(scene, spp=16)
    assert local.sum_mist is not None and local.sum_data is not None and local.sum_light is not None
    for name in ("sum_rgba", "sum_lum2", "sum_normal", "sum_albedo", "min_depth", "count", "sum_mist", "sum_data",
                 "sum_light"):
        assert np.array_equal(getattr(film, name), getattr(local, name)), name
    assert np.array_equal(film.combined, local.combined)
    for layer in ("object", "material"):  # (Cryptomatte's slots merge by id)
        assert np.array_equal(film.cryptomatte(layer), local.cryptomatte(layer)), layer
    assert film.crypto_names == local.crypto_names and film.cryptomatte("asset") is None
    assert film.meta["sample_count"] == 16 and film.meta["spp"] == 16


def test_sample_ranges_on_the_cluster_match_the_local_render(cluster, monkeypatch):
    """Cut into sample ranges too (planned on the client): sums regrouped, within 1e-5."""
    monkeypatch.setattr(plan, "MAX_TILE_TASK_FACTOR", 0.0)
    monkeypatch.setattr(plan, "MIN_TASK_PATHS", 1)
    scene = small_box(32, 24)
    scene.render = replace(scene.render, cryptomatte=("asset",))
    specs = plan.plan_frame((0, 0, 32, 24), 0, 16, min_tasks=4, task_seconds=1e-9)
    assert len({s.sample_offset for s in specs}) > 1
    film, stats = cluster_render(cluster.scheduler_address, scene, 16, task_seconds=1e-9)
    assert stats.tasks_total == len(specs)
    local = render(scene, spp=16)
    a, b = film.combined, local.combined
    assert np.array_equal(film.count, local.count)
    assert np.all(np.abs(a - b) <= 1e-5 * np.maximum(np.abs(b), 1e-6))
    ca, cb = film.cryptomatte("asset"), local.cryptomatte("asset")
    assert np.array_equal(ca[..., 0], cb[..., 0]) and np.allclose(ca[..., 1], cb[..., 1], atol=1e-6)
    assert not np.array_equal(film.sum_rgba, np.zeros_like(film.sum_rgba))


def run_cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "drt", "render", *args], capture_output=True,
                          text=True, timeout=timeout, env=dict(os.environ))


def test_cli_on_the_cluster_writes_the_local_image(cluster, tmp_path):
    common = [BOX, "--spp", "4", "--resolution", "40x32"]
    local = run_cli(*common, "-o", str(tmp_path / "local.exr"))
    assert local.returncode == 0, local.stderr
    env_cluster = subprocess.run(
        [sys.executable, "-m", "drt", "render", *common, "-o", str(tmp_path / "farm.exr"),
         "--task-seconds", "0.01"],
        capture_output=True, text=True, timeout=120,
        env=dict(os.environ, DRT_CLUSTER=cluster.scheduler_address))  # the address from the environment
    assert env_cluster.returncode == 0, env_cluster.stderr
    assert "on 2 workers" in env_cluster.stdout and "Traceback" not in env_cluster.stderr
    a, meta_a = read_exr(tmp_path / "local.exr")
    b, meta_b = read_exr(tmp_path / "farm.exr")
    assert set(a) == set(b)
    for k in a:
        assert np.array_equal(a[k], b[k]), k
    assert meta_b["sample_count"] == "4" and meta_b["seed"] == meta_a["seed"]


def test_a_worker_killed_mid_render_changes_nothing(cluster, tmp_path):
    """SIGKILL a worker process while it holds render tasks: Dask reruns them on the other
    worker, the command exits 0 and the image is the local render's, bit for bit."""
    common = [BOX, "--spp", "64", "--resolution", "96x96"]
    observer = distributed.Client(cluster.scheduler_address, set_as_default=False)
    try:
        pids = observer.run(os.getpid)
        proc = subprocess.Popen([sys.executable, "-m", "drt", "render", *common, "-o", str(tmp_path / "farm.exr"),
                                 "--cluster", cluster.scheduler_address, "--task-seconds", "0.01"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ))
        killed = None
        deadline = time.monotonic() + 60
        while killed is None and proc.poll() is None and time.monotonic() < deadline:
            for worker, keys in observer.processing().items():
                if any(str(k).startswith("drt-render") for k in keys) and worker in pids:
                    os.kill(pids[worker], signal.SIGKILL)
                    killed = worker
                    break
            time.sleep(0.02)
        out, err = proc.communicate(timeout=120)
    finally:
        observer.close()
    assert killed is not None, "the render finished before a worker could be killed"
    assert proc.returncode == 0, err
    local = render(small_box(96, 96), spp=64)
    b, meta = read_exr(tmp_path / "farm.exr")
    for i, c in enumerate("RGBA"):
        assert np.array_equal(b[c], local.combined[..., i]), c
    assert np.array_equal(b["SampleCount.Y"], local.sample_count) and meta["sample_count"] == "64"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_dead_address_is_a_one_line_error_within_the_time_out(tmp_path):
    t0 = time.monotonic()
    r = run_cli(BOX, "-o", str(tmp_path / "x.exr"), "--cluster", f"tcp://127.0.0.1:{free_port()}",
                "--cluster-timeout", "1")
    elapsed = time.monotonic() - t0
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("drt: error: cannot reach the Dask scheduler"), r.stderr
    assert elapsed < 1 + 15  # the time-out plus the interpreter's start (imports)
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("args,message", [
    (["--cluster", "localhost:8786"], "a cluster address is tcp://"),
    (["--cluster", "tcp://127.0.0.1:1", "--threads", "2"], "--threads does not apply"),
    (["--cluster", "tcp://127.0.0.1:1", "--tls-ca-file", "ca.pem"], "need a tls:// scheduler"),
    (["--frames", "1-3"], "--frames needs an animated scene file"),
    (["--cluster-timeout", "0"], "must be within"),
])
def test_bad_cluster_options_are_one_line_errors(args, message, tmp_path, capsys):
    from drt.cli import main

    with pytest.raises(SystemExit) if "must be within" in message else _nothing():
        code = main(["render", BOX, "-o", str(tmp_path / "x.exr"), *args])
        assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and "Traceback" not in "".join(err)


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_no_cluster_imports_no_dask(tmp_path):
    code = ("import sys; from drt.cli import main; "
            f"rc = main(['render', {BOX!r}, '-o', {str(tmp_path / 'x.exr')!r}, '--spp', '1', '--resolution', '8x8']); "
            "assert rc == 0; assert 'distributed' not in sys.modules and 'dask' not in sys.modules, 'dask imported'")
    env = {k: v for k, v in os.environ.items() if k != "DRT_CLUSTER"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr


# ----------------------------------------------------------------------------------- TLS


def make_certificates(folder):
    """A self-signed CA and one certificate it signed (for scheduler, workers and client)."""
    if subprocess.run(["openssl", "version"], capture_output=True).returncode != 0:
        pytest.skip("needs the openssl command")

    def ssl(*args):
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=folder)

    ssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj", "/CN=drt-test-ca",
        "-keyout", "ca.key", "-out", "ca.pem")
    ssl("req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=drt-test-node", "-keyout", "node.key", "-out", "node.csr")
    ssl("x509", "-req", "-in", "node.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-days", "2",
        "-out", "node.pem")
    return {k: os.path.join(folder, f) for k, f in (("ca", "ca.pem"), ("cert", "node.pem"), ("key", "node.key"))}


def test_tls_round_trip_with_a_self_signed_ca(tmp_path):
    from distributed.security import Security

    certs = make_certificates(tmp_path)
    sec = Security(tls_ca_file=certs["ca"], tls_scheduler_cert=certs["cert"], tls_scheduler_key=certs["key"],
                   tls_worker_cert=certs["cert"], tls_worker_key=certs["key"], tls_client_cert=certs["cert"],
                   tls_client_key=certs["key"], require_encryption=True)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  protocol="tls://", security=sec, dashboard_address=":0", silence_logs=50) as c:
        address = c.scheduler_address
        assert address.startswith("tls://")
        out = tmp_path / "tls.exr"
        r = run_cli(BOX, "-o", str(out), "--spp", "2", "--resolution", "24x16", "--cluster", address,
                    "--tls-ca-file", certs["ca"], "--tls-cert", certs["cert"], "--tls-key", certs["key"])
        assert r.returncode == 0, r.stderr
        ch, _ = read_exr(out)
        local = render(small_box(24, 16), spp=2)
        assert np.array_equal(ch["R"], local.combined[..., 0])
        # without the certificates the scheduler refuses the client (exit 2 in the CLI)
        with pytest.raises(FarmError, match="cannot reach the Dask scheduler") as e:
            connect(address.replace("tls://", "tcp://"), timeout=1)
        assert e.value.code == 2


def test_connect_refuses_an_empty_cluster():
    with distributed.LocalCluster(n_workers=0, processes=True, host="127.0.0.1", dashboard_address=":0",
                                  silence_logs=50) as c:
        t0 = time.monotonic()
        with pytest.raises(FarmError, match="has no workers") as e:
            connect(c.scheduler_address, timeout=1)
        assert e.value.code == 2 and time.monotonic() - t0 < 10


# ------------------------------------------------------------------------------- animations


def test_frames_locally_and_on_the_cluster_are_numbered_and_identical(cluster, tmp_path, capsys):
    """--frames 1-2 of an animated .blend: OUT_##.exr numbering, each frame exported on the
    client; frames and their tiles scheduled together on the cluster; same images as local."""
    pytest.importorskip("bpy")
    from drt.cli import main

    blend = os.path.join(REPO, "blend_scenes", "motion_blur.blend")
    common = ["render", blend, "--frames", "1-2", "--spp", "2", "--resolution", "32x24"]
    assert main([*common, "-o", str(tmp_path / "local_##.exr")]) == 0
    assert main([*common, "-o", str(tmp_path / "farm.exr"), "--cluster", cluster.scheduler_address,
                 "--task-seconds", "0.01"]) == 0
    assert "2 frames on 2 workers" in capsys.readouterr().out
    assert sorted(os.listdir(tmp_path)) == ["farm0001.exr", "farm0002.exr", "local_01.exr", "local_02.exr"]
    images = []
    for f in (1, 2):
        a, _ = read_exr(tmp_path / f"local_{f:02d}.exr")
        b, meta = read_exr(tmp_path / f"farm{f:04d}.exr")
        for k in a:
            assert np.array_equal(a[k], b[k]), (f, k)
        images.append(a["R"])
    assert not np.array_equal(images[0], images[1])  # the frames differ: something moves


@pytest.mark.slow
def test_all_workers_gone_is_a_clear_error_within_the_time_out():
    """The only worker leaves mid-render and none comes back: FarmError after the time-out."""
    scene = small_box(64, 64)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=":0", silence_logs=50) as c:
        client = connect(c.scheduler_address, timeout=1)
        state = {}

        def progress(fraction, stats):
            if "t" not in state:  # the first task is back: retire the worker
                state["t"] = time.monotonic()
                c.scale(0)

        try:
            with pytest.raises(FarmError, match="all workers left the cluster") as e:
                render_frames(client, [None], lambda f: (scene, scene), {"spp": 256}, on_frame=lambda f, film: None,
                              timeout=1, task_seconds=0.01, progress=progress)
        finally:
            client.close()
        assert e.value.code == 1 and time.monotonic() - state["t"] < 15


@pytest.mark.slow
def test_ctrl_c_cancels_the_cluster_tasks_and_writes_the_finished_tiles(cluster, tmp_path):
    out = tmp_path / "partial.exr"
    proc = subprocess.Popen([sys.executable, "-m", "drt", "render", BOX, "-o", str(out), "--spp", "100000",
                             "--resolution", "64x64", "--cluster", cluster.scheduler_address],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    observer = distributed.Client(cluster.scheduler_address, set_as_default=False)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any(
                str(k).startswith("drt-render") for keys in observer.processing().values() for k in keys):
            time.sleep(0.05)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err
        deadline = time.monotonic() + 15  # the scheduler forgets the cancelled tasks
        while time.monotonic() < deadline:
            left = [k for keys in observer.processing().values() for k in keys if str(k).startswith("drt-render")]
            if not left:
                break
            time.sleep(0.1)
        assert not left
    finally:
        observer.close()
    if out.exists():  # the tiles finished before Ctrl-C (none may have, at 100000 spp)
        ch, _ = read_exr(out)
        assert ch["R"].shape == (64, 64)


@pytest.mark.slow
def test_the_only_worker_killed_and_restarted_changes_nothing():
    """The one worker holding the scene dies (its nanny starts a fresh one): the scene is lost
    with it, Dask cancels the tasks that needed it, DRT sends the scene again and resubmits
    them; the image is still the local render's."""
    scene = small_box(64, 64)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=":0", silence_logs=50) as c:
        client = connect(c.scheduler_address, timeout=30)
        (pid,) = client.run(os.getpid).values()
        films, state = {}, {}

        def progress(fraction, stats):
            if "killed" not in state:
                state["killed"] = True
                os.kill(pid, signal.SIGKILL)

        try:
            stats = render_frames(client, [None], lambda f: (scene, scene), {"spp": 64},
                                  on_frame=lambda f, film: films.setdefault(f, film), timeout=30,
                                  task_seconds=0.01, progress=progress)
        finally:
            client.close()
    assert state["killed"] and stats.tasks_done == stats.tasks_total and stats.resubmitted > 0
    local = render(scene, spp=64)
    assert np.array_equal(films[None].sum_rgba, local.sum_rgba)


def test_denoise_on_the_cluster_runs_once_on_the_merged_frame(cluster, tmp_path):
    """Issue 15's farm rule: the cluster's tiles are merged on the client and denoised once, so
    the result equals the local render with --denoise (same noisy image, same denoiser input)."""
    pytest.importorskip("pyoidn")
    common = [BOX, "--spp", "4", "--resolution", "40x32", "--denoise", "--denoise-quality", "fast"]
    local = run_cli(*common, "-o", str(tmp_path / "local.exr"))
    assert local.returncode == 0, local.stderr
    farm = run_cli(*common, "-o", str(tmp_path / "farm.exr"), "--cluster", cluster.scheduler_address,
                   "--task-seconds", "0.01")
    assert farm.returncode == 0, farm.stderr
    assert "denoised" in farm.stdout
    a, _ = read_exr(tmp_path / "local.exr")
    b, meta = read_exr(tmp_path / "farm.exr")
    assert "Noisy.R" in b and np.array_equal(a["Noisy.R"], b["Noisy.R"])
    for c in "RGB":
        assert np.array_equal(a[c], b[c]), c  # one denoise of the same merged image
    assert not np.array_equal(b["R"], b["Noisy.R"])
    assert "denoised" in meta
