"""`vibinverse.parallel.thread_map`: the items' order, one thread's numbers, errors raised."""

import threading

import pytest

from vibinverse.parallel import thread_map


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
