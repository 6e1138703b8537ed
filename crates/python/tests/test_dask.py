"""mdtf.dask on a 2-worker process cluster: blocks of an OME-Zarr store
with chunks that do not divide the shape give what the whole-volume calls
give, bit for bit, and whole pipeline runs give ``mdtf run``'s files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

import mdtf

distributed = pytest.importorskip("distributed", reason="mdtf.dask's tests need dask.distributed")
import mdtf.dask as mdask  # noqa: E402
from conftest import cli  # noqa: E402

import dask  # noqa: E402


@pytest.fixture(scope="module")
def client() -> Iterator[distributed.Client]:
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


@pytest.fixture(scope="module")
def store(sphere: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("zarr") / "sphere.ome.zarr"
    mdtf.write(path, mdtf.read(sphere))
    return path


def test_the_store_reads_as_the_volume(store: Path, sphere: Path) -> None:
    arr, spacing = mdask.from_ome_zarr(store, chunks=(13, 17, 19))
    vol = mdtf.read(sphere)
    assert spacing == pytest.approx(vol.spacing)
    assert arr.chunks[0] == (13, 13, 13, 9) and arr.shape == vol.data.shape
    np.testing.assert_array_equal(arr.compute(), vol.data)


@pytest.mark.parametrize(("kernel", "border"), [(None, None), ("gauss:1.5", "mirror"), ("bspline3", "wrap")])
def test_derive_by_blocks_equals_the_whole(
    client: distributed.Client, store: Path, sphere: Path, kernel: str | None, border: str | None
) -> None:
    arr, spacing = mdask.from_ome_zarr(store, chunks=(13, 17, 19))
    items = ["g", "f2", "normal", "inv_g"]
    lazy = mdask.derive(arr, spacing, items=items, kernel=kernel, border=border)
    got = dict(zip(lazy, client.compute(list(lazy.values()), sync=True)))
    vol = mdtf.read(sphere)
    want = mdtf.derive(vol.data, vol.spacing, items=items, kernel=kernel, border=border)
    assert set(got) == set(want) == {"g", "f2", "nx", "ny", "nz", "inv_g"}
    for name in want:
        np.testing.assert_array_equal(got[name], want[name], err_msg=f"{name}, kernel {kernel}, border {border}")


def test_bilateral_by_blocks_equals_the_whole(client: distributed.Client, store: Path, sphere: Path) -> None:
    arr, spacing = mdask.from_ome_zarr(store, chunks=(13, 17, 19))
    got = client.compute(mdask.bilateral(arr, spacing, sigma_d=1.5, sigma_r=0.1), sync=True)
    vol = mdtf.read(sphere)
    np.testing.assert_array_equal(got, mdtf.bilateral(vol.data, vol.spacing, sigma_d=1.5, sigma_r=0.1))


def test_results_go_to_an_ome_zarr_store_mdtf_and_ome_zarr_models_read(
    client: distributed.Client, store: Path, sphere: Path, tmp_path: Path
) -> None:
    arr, spacing = mdask.from_ome_zarr(store, chunks=(13, 17, 19))
    g = mdask.derive(arr, spacing, items=["g"])["g"]
    out = tmp_path / "g.ome.zarr"
    assert mdask.to_ome_zarr(g, out, spacing, origin=(1.0, 2.0, 3.0)) == str(out)
    vol = mdtf.read(sphere)
    back = mdtf.read(out)
    np.testing.assert_array_equal(back.data, mdtf.derive(vol.data, vol.spacing, items=["g"])["g"])
    assert back.spacing == pytest.approx(vol.spacing) and back.origin == pytest.approx((1.0, 2.0, 3.0))
    from ome_zarr_models.v05.image import Image

    Image.from_zarr(__import__("zarr").open_group(str(out), mode="r"))
    assert [p.name for p in tmp_path.iterdir()] == ["g.ome.zarr"], "no staging folder left"
    with pytest.raises(FileExistsError):
        mdask.to_ome_zarr(g, out, spacing)


def test_the_median_is_exact() -> None:
    rng = np.random.default_rng(5)
    data = rng.gamma(2.0, 3.0, size=(21, 22, 23)).astype(np.float32)
    data[0, 0, :5] = np.nan
    arr = mdask.da.from_array(data, chunks=(5, 7, 9))
    finite = np.sort(data[np.isfinite(data)])
    assert mdask.lower_median(arr) == float(finite[(finite.size - 1) // 2])
    assert mdask.lower_median(mdask.da.full((4, 4, 4), np.nan, dtype=np.float32, chunks=2)) is None


def test_boundary_by_blocks_equals_the_whole(client: distributed.Client, store: Path, sphere: Path) -> None:
    arr, spacing = mdask.from_ome_zarr(store, chunks=(13, 17, 19))
    lazy = mdask.boundary(arr, spacing, kernel="gauss:1", d_max=6.0)
    got = dict(zip(lazy, client.compute(list(lazy.values()), sync=True)))
    vol = mdtf.read(sphere)
    want = mdtf.boundary(vol.data, vol.spacing, kernel="gauss:1", d_max=6.0)
    assert (want.hit == 1).sum() > 1000
    for name in ["distance", "g_hit", "hit", "dot"]:
        np.testing.assert_array_equal(got[name], getattr(want, name), err_msg=name)


def test_a_worker_killed_mid_run_changes_nothing(client: distributed.Client, sphere: Path) -> None:
    vol = mdtf.read(sphere)
    big = np.tile(vol.data, (2, 2, 2))
    lazy = mdask.bilateral(mdask.da.from_array(big, chunks=(24, 30, 26)), vol.spacing, sigma_d=3.0)
    future = client.compute(lazy)
    # once the first blocks are done, one worker process dies with what it holds and runs
    deadline = time.monotonic() + 60
    while not any(client.processing().values()) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    assert not future.done(), "the run ended before a worker could be killed"
    victim = next(iter(client.scheduler_info()["workers"]))
    pid = client.run(os.getpid, workers=[victim])[victim]
    os.kill(pid, signal.SIGKILL)
    got = future.result(timeout=300)
    np.testing.assert_array_equal(got, mdtf.bilateral(big, vol.spacing, sigma_d=3.0))


def test_thin_edge_chunks_are_merged_not_refused(sphere: Path) -> None:
    vol = mdtf.read(sphere)
    arr = mdask.da.from_array(vol.data, chunks=((1, 20, 26, 1), (2, 42), (40,)))
    got = mdask.derive(arr, vol.spacing, items=["g"])["g"].compute(scheduler="threads")
    np.testing.assert_array_equal(got, mdtf.derive(vol.data, vol.spacing, items=["g"])["g"])


def test_halos_are_the_stages_reach() -> None:
    # central4: two samples each side; a Gaussian of sigma 1.5 world units cut at 4 sigma: ceil(6 / spacing)
    assert mdtf._mdtf.kernel_reach((1.0, 1.0, 1.0), None) == (2, 2, 2)
    assert mdtf._mdtf.kernel_reach((2.0, 1.0, 0.5), "gauss:1.5") == (3, 6, 12)
    # bilateral exact: ceil(2.5 sigma_d / spacing)
    assert mdtf._mdtf.bilateral_reach((1.2, 1.0, 0.8), 1.5, "exact", None) == (4, 4, 5)


def _outputs(folder: Path) -> dict[str, bytes]:
    """Every file a run wrote (relative path -> bytes), but the run report and
    its page, which hold timings and how the run was cut."""
    skip = {"run_report.json", "report.html", ".mdtf-output"}
    return {
        str(f.relative_to(folder)): f.read_bytes()
        for f in sorted(folder.rglob("*"))
        if f.is_file() and str(f.relative_to(folder)) not in skip
    }


@pytest.fixture(scope="module")
def chunked_store(sphere: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sphere as an OME-Zarr store of 13 x 17 x 19 chunks (none divides its 48 x 44 x 40)."""
    vol = mdtf.read(sphere)
    path = tmp_path_factory.mktemp("chunked") / "sphere.ome.zarr"
    mdask.to_ome_zarr(mdask.da.from_array(vol.data, chunks=(13, 17, 19)), path, vol.spacing, vol.origin)
    return path


@pytest.mark.parametrize("name", ["slicer-3dtf", "distance-tf"])
def test_a_pipeline_run_on_the_cluster_writes_mdtf_runs_files(
    client: distributed.Client,
    chunked_store: Path,
    mdtf_bin: Path,
    pipelines: Path,
    tmp_path: Path,
    name: str,
    capfd: pytest.CaptureFixture[str],
) -> None:
    pipeline = pipelines / f"{name}.toml"
    cli(mdtf_bin, "run", pipeline, "--input", chunked_store, "-o", tmp_path / "cli", "--set", "preview=false")
    report = mdask.run(pipeline, tmp_path / "dask", input=chunked_store, client=client, slab_planes=13, preview=False)
    slabs = report["slabs"]
    assert {k: slabs[k] for k in ("planes", "count", "budget")} == {"planes": 13, "count": 4, "budget": None}
    # every pass ran on the cluster, the store read by the tasks, none rerun
    passes = [t["pass"] for t in slabs["tasks"]]
    # distance-tf: the tracing, then its kept distance and g_hit written by the tasks
    traced = ["prefilter", "select", "boundary", "keep"] if name == "distance-tf" else []
    assert passes == ["input", "derive", *traced, "pack"], slabs["tasks"]
    assert all(t["retries"] == 0 for t in slabs["tasks"]), slabs["tasks"]
    # each pass said how far its tasks got
    err = capfd.readouterr().err
    for t in slabs["tasks"]:
        line = f"mdtf.dask.run: {t['pass']}: {t['tasks']}/{t['tasks']} tasks in "
        assert line in err, err
    want, got = _outputs(tmp_path / "cli"), _outputs(tmp_path / "dask")
    assert any(f.startswith("pack/") and f.endswith(".raw") for f in want), sorted(want)
    assert sorted(got) == sorted(want)
    assert [f for f in want if got[f] != want[f]] == []
    assert not (tmp_path / "dask" / ".slabs").exists()


@pytest.fixture(scope="module")
def sphere96(mdtf_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A noisy 96^3 erf sphere (a run long enough to interrupt)."""
    path = tmp_path_factory.mktemp("sphere96") / "sphere96.nrrd"
    cli(mdtf_bin, "synth", "erf-sphere", "--size", "96", "--noise", "2", "-o", path)
    return path


def _once_tasks_run(client: distributed.Client) -> None:
    """Returns once the cluster is running tasks (or after two minutes)."""
    deadline = time.monotonic() + 120
    while not any(client.processing().values()) and time.monotonic() < deadline:
        time.sleep(0.02)


def test_a_worker_killed_in_a_pipeline_run_changes_nothing(
    client: distributed.Client, sphere96: Path, mdtf_bin: Path, pipelines: Path, tmp_path: Path
) -> None:
    pipeline = pipelines / "distance-tf.toml"
    cli(mdtf_bin, "run", pipeline, "--input", sphere96, "-o", tmp_path / "cli", "--set", "preview=false")
    result: dict[str, object] = {}

    def go() -> None:
        try:
            result["report"] = mdask.run(pipeline, tmp_path / "dask", input=sphere96, client=client, slab_planes=6, preview=False)
        except BaseException as e:  # noqa: BLE001 - handed to the test thread
            result["error"] = e

    runner = threading.Thread(target=go)
    runner.start()
    # once tasks are running, one worker process dies with what it holds and runs
    _once_tasks_run(client)
    assert runner.is_alive(), "the run ended before a worker could be killed"
    victim = next(iter(client.scheduler_info()["workers"]))
    pid = client.run(os.getpid, workers=[victim])[victim]
    os.kill(pid, signal.SIGKILL)
    runner.join(timeout=600)
    assert "error" not in result, result.get("error")
    want, got = _outputs(tmp_path / "cli"), _outputs(tmp_path / "dask")
    assert sorted(got) == sorted(want)
    assert [f for f in want if got[f] != want[f]] == []


_DRIVER = """
import sys
import mdtf.dask as mdask
mdask.run(sys.argv[1], sys.argv[2], input=sys.argv[3], slab_planes=6, preview=False)
"""


def test_a_run_whose_driver_was_killed_resumes_with_the_same_files(
    sphere96: Path, mdtf_bin: Path, pipelines: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    pipeline = pipelines / "distance-tf.toml"
    out = tmp_path / "out"
    cli(mdtf_bin, "run", pipeline, "--input", sphere96, "-o", tmp_path / "cli", "--set", "preview=false")
    # the driver (dask's own scheduler, in its process) is killed once its tracing pass has begun
    args = [sys.executable, "-c", _DRIVER, str(pipeline), str(out), str(sphere96)]
    driver = subprocess.Popen(args, stderr=subprocess.PIPE, text=True)
    assert driver.stderr is not None
    seen = []
    for line in driver.stderr:
        seen.append(line)
        if line.startswith("mdtf.dask.run: select: "):
            driver.kill()
            break
    driver.wait(timeout=120)
    assert driver.returncode == -signal.SIGKILL, "".join(seen)
    partial = [p.name for p in tmp_path.iterdir() if p.name.startswith(".mdtf-partial-out-")]
    assert len(partial) == 1 and not out.exists(), sorted(p.name for p in tmp_path.iterdir())
    capfd.readouterr()
    report = mdask.run(pipeline, out, input=sphere96, slab_planes=6, preview=False)
    slabs = report["slabs"]
    assert slabs["resumed"] is True
    tasks = {t["pass"]: t for t in slabs["tasks"]}
    assert list(tasks) == ["derive", "prefilter", "select", "boundary", "keep", "pack"]
    # the passes that had finished ran no task again; the rest did
    assert all(tasks[p]["reused"] == tasks[p]["tasks"] for p in ("derive", "prefilter", "select")), tasks
    assert sum(t["tasks"] - t["reused"] for t in tasks.values()) > 0, tasks
    # and said so as each pass ended
    err = capfd.readouterr().err
    n = tasks["derive"]["tasks"]
    assert f"mdtf.dask.run: derive: {n}/{n} tasks in " in err and f"({n} found their slab done by the run this one resumes)" in err, err
    want, got = _outputs(tmp_path / "cli"), _outputs(out)
    assert sorted(got) == sorted(want)
    assert [f for f in want if got[f] != want[f]] == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cli", "out"], "no partial folder is left"
    # resume=False starts afresh
    again = mdask.run(pipeline, out, input=sphere96, slab_planes=6, preview=False, progress=False, resume=False)
    assert "resumed" not in again["slabs"] and all(t["reused"] == 0 for t in again["slabs"]["tasks"])


def test_ctrl_c_during_a_pipeline_run_drops_its_tasks_and_leaves_nothing(
    client: distributed.Client, sphere96: Path, pipelines: Path, tmp_path: Path
) -> None:
    signalled: list[float] = []

    def interrupt() -> None:
        _once_tasks_run(client)
        signalled.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)

    # Python's own Ctrl-C handler, even under a background job that ignores SIGINT
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        threading.Thread(target=interrupt, daemon=True).start()
        with pytest.raises(KeyboardInterrupt):
            mdask.run(
                pipelines / "distance-tf.toml", tmp_path / "out", input=sphere96, client=client, slab_planes=4, preview=False
            )
    finally:
        signal.signal(signal.SIGINT, previous)
    assert signalled and time.monotonic() - signalled[0] < 2.0, "interrupted within two seconds"
    assert list(tmp_path.iterdir()) == [], "no output and no partial folder"


def test_a_pipeline_run_without_a_cluster_uses_dasks_scheduler_and_fails_as_mdtf_run(
    sphere: Path, pipelines: Path, tmp_path: Path
) -> None:
    with dask.config.set(scheduler="threads"):
        report = mdask.run(pipelines / "distance-tf.toml", tmp_path / "out", input=sphere, slab_planes=20, preview=False)
    assert report["slabs"]["count"] == 3 and report["boundary"]["counts"]["hits"] > 1000
    with pytest.raises(mdtf.MdtfError, match="boundary.d_max"):
        mdask.run(pipelines / "distance-tf.toml", tmp_path / "bad", input=sphere, boundary__d_max=-1.0)
    assert not (tmp_path / "bad").exists()
