""":func:`fxflex.bench.common.median_time`: how a benchmark times a route of milliseconds."""

import itertools

import pytest
from mpi4py import MPI

from fxflex.bench import common


def _clock(monkeypatch, durations):
    """perf_counter that makes the k-th call of the timed function last durations[k]."""
    ticks = itertools.accumulate(x for d in durations for x in (0.0, d))
    monkeypatch.setattr(common.time, "perf_counter", lambda: next(ticks))


def test_repeats_until_the_budget_and_returns_the_first_result_and_the_median(monkeypatch):
    _clock(monkeypatch, [0.3, 0.1, 0.2, 0.05, 9.0])
    calls = itertools.count()
    out, median, runs = common.median_time(lambda: next(calls), budget=0.55)
    assert out == 0 and runs == 3                 # 0.3 + 0.1 + 0.2 >= 0.55: stop
    assert median == pytest.approx(0.2)           # of 0.1, 0.2, 0.3


def test_a_slow_route_runs_once_and_the_count_is_capped(monkeypatch):
    _clock(monkeypatch, [2.0])
    assert common.median_time(lambda: "x", budget=0.5)[1:] == (2.0, 1)
    _clock(monkeypatch, [0.01] * 10)
    out, median, runs = common.median_time(lambda: None, budget=10.0, most=4)
    assert runs == 4 and median == pytest.approx(0.01)    # even count: mean of the middle two


def test_ranks_agree_on_the_count():
    """Every rank runs a collective route as often as the others (the slowest rank's time)."""
    comm = MPI.COMM_WORLD
    delay = 0.02 if comm.rank == 0 else 0.0
    import time

    _, _, runs = common.median_time(lambda: (time.sleep(delay), comm.barrier()), comm,
                                    budget=0.1)
    assert len(set(comm.allgather(runs))) == 1
