"""vibinverse.bench.limited_processes: steps in their own processes, each cut at its limit."""

import time

from vibinverse.bench.limited_processes import Step, run_jobs


def _sleep(seconds: float) -> dict:
    time.sleep(seconds)
    return {"slept": seconds}


def _fail() -> dict:
    raise ValueError("bad input\nsecond line")


def _two_steps(first: float, limit: float):
    a = yield Step("a", _sleep, (first,), limit)
    b = yield Step("b", _fail, (), limit)
    return [{"a": a.status, "b": b.status, "b_error": b.error, "value": a.value}]


def test_steps_run_in_processes_and_a_slow_one_is_cut_at_its_limit():
    out = run_jobs([_two_steps(0.05, 5.0), _two_steps(30.0, 0.5)], workers=2)
    assert out[0] == [{"a": "ok", "b": "error", "b_error": "ValueError: bad input", "value": {"slept": 0.05}}]
    assert out[1][0]["a"] == "timeout" and out[1][0]["value"] is None
