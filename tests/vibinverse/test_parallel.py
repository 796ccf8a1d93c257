"""`vibinverse.parallel.thread_map`: the items' order, one thread's numbers, errors raised."""

import threading

import pytest

from vibinverse.errors import InputError
from vibinverse.parallel import MAX_DEFAULT_WORKERS, WORKERS_VARIABLE, default_workers, thread_map


def test_results_keep_the_items_order_on_several_threads():
    seen = set()

    def slow_square(x):
        seen.add(threading.get_ident())
        threading.Event().wait(0.002 * (10 - x))  # later items finish first
        return x * x

    assert thread_map(slow_square, range(10), workers=3) == [x * x for x in range(10)]
    assert len(seen) > 1


def test_one_worker_or_one_item_runs_in_the_calling_thread():
    me = threading.get_ident()
    assert thread_map(lambda x: threading.get_ident(), [1, 2, 3], workers=1) == [me] * 3
    assert thread_map(lambda x: threading.get_ident(), [1], workers=4) == [me]
    assert thread_map(lambda x: x, [], workers=4) == []


def test_an_exception_in_a_thread_is_raised_to_the_caller():
    def fail_on_three(x):
        if x == 3:
            raise ValueError("three")
        return x

    with pytest.raises(ValueError, match="three"):
        thread_map(fail_on_three, range(6), workers=2)


def test_a_fit_s_default_threads_are_the_process_s_cores_up_to_the_cap(monkeypatch):
    monkeypatch.delenv(WORKERS_VARIABLE, raising=False)
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1, 2, 3, 4, 5, 6, 7, 8, 9}, raising=False)
    assert default_workers() == MAX_DEFAULT_WORKERS
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {3}, raising=False)
    assert default_workers() == 1
    monkeypatch.delattr("os.sched_getaffinity", raising=False)
    monkeypatch.setattr("os.cpu_count", lambda: None)
    assert default_workers() == 1


@pytest.mark.parametrize("told, threads", [("3", 3), (" 1 ", 1), ("0", None), ("two", None), ("-2", None)])
def test_the_environment_sets_a_fit_s_default_threads_or_is_refused_in_one_line(monkeypatch, told, threads):
    monkeypatch.setenv(WORKERS_VARIABLE, told)
    if threads is None:
        with pytest.raises(InputError, match=rf"^{WORKERS_VARIABLE}: .*allowed: an integer >= 1$"):
            default_workers()
    else:
        assert default_workers() == threads
