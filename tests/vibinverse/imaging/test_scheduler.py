"""Where Dask work runs: local threads (their number), an in-process dask.distributed cluster giving
the same detection map as local threads, and one-line errors for a scheduler that does not answer."""

import logging
import threading
import time

import dask
import dask.array as da
import numpy as np
import pytest
import xarray as xr

from vibinverse.errors import DataError, InputError
from vibinverse.imaging.detection_map import detection_map
from vibinverse.imaging.scheduler import compute, default_workers, session

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def cluster():
    """An in-process cluster (threads, no subprocesses): 2 workers of 1 thread."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as c:
        yield c


def test_local_threads_run_at_most_workers_tasks_at_once():
    running, peak, lock = [0], [0], threading.Lock()

    def task(i):
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        time.sleep(0.05)
        with lock:
            running[0] -= 1
        return i

    tasks = [dask.delayed(task)(i) for i in range(8)]
    with session(None, 3) as run:
        assert run.threads == 3 and run.address is None
        assert list(run.compute(*tasks)) == list(range(8))
    assert peak[0] == 3  # 8 sleeping tasks on 3 threads: exactly 3 at once
    with session() as run:
        assert run.threads == default_workers() >= 1


def test_compute_gives_what_dask_gives():
    x = da.arange(100, chunks=7)
    assert compute(x.sum(), (x**2).sum(), workers=2) == (4950, 328350)


@pytest.mark.parametrize("workers", [0, -1, 1.5, True, "2"])
def test_bad_workers_are_one_line_errors(workers):
    with pytest.raises(InputError, match=r"^--workers: .* is not a number of threads \(an integer >= 1\)$"):
        compute(da.ones(3).sum(), workers=workers)


def test_the_same_map_on_a_cluster_as_on_local_threads(cluster, caplog):
    rng = np.random.default_rng(21)
    nt, n = 512, 20
    t = np.arange(nt) / 100.0
    data = rng.standard_normal((nt, n, n))
    data[:, 5:9, 5:9] += np.sin(2 * np.pi * 9.7 * t)[:, None, None]
    cube = xr.DataArray(da.from_array(data, chunks=(128, n, n)), dims=("time", "y", "x"), coords={"time": t})
    with session(cluster.scheduler_address) as run:
        assert run.threads == 2 and run.address == cluster.scheduler_address
    local = detection_map(cube, workers=2, memory=2 * 2**20)
    with caplog.at_level(logging.WARNING):
        remote = detection_map(cube, scheduler=cluster.scheduler_address, workers=3, memory=2 * 2**20)
    assert "--workers is ignored with --scheduler" in caplog.text
    assert len(remote.lines) == 1 and abs(remote.lines[0].frequency - 9.7) < 100.0 / nt
    for name in ("peak_snr", "peak_frequency", "snr", "cluster", "false_alarm_probability"):
        np.testing.assert_array_equal(remote.maps[name].values, local.maps[name].values, err_msg=name)


def test_an_error_inside_a_task_comes_back_as_itself(cluster):
    def bad(_):
        raise DataError("input: frame 3 cannot be decoded")

    with pytest.raises(DataError, match="frame 3"):
        compute(dask.delayed(bad)(1), scheduler=cluster.scheduler_address)


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:1", "nonsense::"])
def test_a_scheduler_that_does_not_answer_is_a_one_line_error(address):
    t0 = time.perf_counter()
    with pytest.raises(InputError) as info, session(address, timeout=1.0):
        pass
    message = str(info.value)
    assert message.startswith(f"--scheduler: cannot connect to {address!r}") and "\n" not in message
    assert time.perf_counter() - t0 < 15  # the timeout, not distributed's 30 s default
