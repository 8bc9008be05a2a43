""":func:`fxflex.bench.common.median_time`: how a benchmark times a route of milliseconds."""

import itertools
import time
import types

import pytest
from mpi4py import MPI

from fxflex.bench import common


def _clock(monkeypatch, durations):
    """A clock (in the module under test only) that makes the k-th run last durations[k]."""
    ticks = itertools.accumulate(x for d in durations for x in (0.0, d))
    monkeypatch.setattr(common, "time", types.SimpleNamespace(perf_counter=lambda: next(ticks)))


def test_repeats_until_the_budget_and_returns_the_first_result_and_the_median(monkeypatch):
    _clock(monkeypatch, [0.3, 0.1, 0.2, 0.05, 9.0])
    calls = itertools.count()
    out, median, runs = common.median_time(lambda: next(calls), budget=0.55)
    assert out == 0 and runs == 3                 # 0.3 + 0.1 + 0.2 >= 0.55: stop
    assert median == pytest.approx(0.2)           # of 0.1, 0.2, 0.3


def test_a_slow_route_runs_once_and_the_count_is_capped(monkeypatch):
    _clock(monkeypatch, [2.0])
    assert common.median_time(lambda: "x", budget=0.5)[1:] == (2.0, 1)
    _clock(monkeypatch, [0.01, 0.03, 0.02, 0.04, 0.05])
    out, median, runs = common.median_time(lambda: None, budget=10.0, most=4)
    assert runs == 4 and median == pytest.approx(0.025)   # even count: mean of the middle two


def test_ranks_agree_on_the_count():
    """A route that is slower on rank 0 runs as often on every rank (each stops on the slowest
    rank's total), so that a collective route cannot be left waiting on one rank."""
    comm = MPI.COMM_WORLD
    delay = 0.02 if comm.rank == 0 else 0.0
    _, _, runs = common.median_time(lambda: time.sleep(delay), comm, budget=0.1)
    counts = comm.allgather(runs)
    assert len(set(counts)) == 1
    if comm.size > 1:
        assert counts[0] < common.MAX_REPEATS       # rank 1 alone would have run 31 times
