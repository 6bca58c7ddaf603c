"""The index's simulated part run beside the paper's part (maglev_match.core.beside).

Beside each other the two parts must give the index they give one after the other, to the
last bit (each part computes what it computed before, in its own thread), and an error or a
Ctrl-C in the caller's part must stop the simulated part before it reaches the caller: no
thread of the package computes on after the index has raised.
"""

from __future__ import annotations

import json
import threading

import pytest

from maglev_match.analyses import continued, matching
from maglev_match.core import beside as beside_mod
from maglev_match.core.beside import Beside, Stopped, stop_point
from maglev_match.core.params import load_preset


def _running_beside() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "maglev-match-beside"]


def test_stop_point_does_nothing_outside_and_stops_the_work_inside():
    stop_point()  # not inside a Beside: nothing happens
    entered = threading.Event()

    def work():
        entered.set()
        while True:  # stops only at a stop point
            stop_point()
            threading.Event().wait(0.001)

    job = Beside(work)
    assert entered.wait(60)
    job.stop()
    assert not _running_beside()
    with pytest.raises(Stopped):
        job.result()


def test_beside_returns_the_value_and_raises_the_error_of_its_work():
    assert Beside(lambda a, b: a + b, 2, 3).result() == 5

    def fails():
        raise ValueError("inside")

    with pytest.raises(ValueError, match="inside"):
        Beside(fails).result()


def test_index_beside_equals_the_index_one_after_the_other(monkeypatch):
    params = load_preset("turnout-soft")
    started = []
    real = beside_mod.Beside.__init__

    def counting(self, fn, *args):
        started.append(fn.__name__)
        real(self, fn, *args)

    monkeypatch.setattr(beside_mod.Beside, "__init__", counting)
    monkeypatch.setattr(matching, "_beside_allowed", lambda m: False)
    one_after = matching.matching_index(params).as_json()
    assert started == []
    monkeypatch.setattr(matching, "_beside_allowed", lambda m: True)
    both = matching.matching_index(params).as_json()
    assert started == ["simulated_part"]
    assert json.dumps(both, sort_keys=True) == json.dumps(one_after, sort_keys=True)
    assert both["simulation"]["up"]["critical"]["converged"]
    assert both["simulation"]["down"]["critical"]["converged"]


def test_a_process_on_one_core_computes_the_parts_one_after_the_other(monkeypatch):
    monkeypatch.setattr(beside_mod.os, "sched_getaffinity", lambda pid: {0})
    assert not beside_mod.two_cores()
    assert not matching._beside_allowed(matching.maglev_model(load_preset("turnout-soft")))


@pytest.mark.parametrize("error", [RuntimeError("the paper's part failed"),
                                   KeyboardInterrupt()])
def test_an_error_in_the_paper_part_stops_the_simulated_part_first(monkeypatch, error):
    """The paper's part raises once the simulated part is inside its kernels: the index
    raises that error, and by then the simulated part has stopped at its next kernel call
    (it ends with Stopped, not with a result) and its thread has ended."""
    from maglev_match.dynamics.integrate import simulate

    in_kernels = threading.Event()
    real_stop_point = simulate.stop_point

    def marking_stop_point():
        in_kernels.set()
        real_stop_point()

    monkeypatch.setattr(simulate, "stop_point", marking_stop_point)
    ended = []
    real_part = continued.simulated_part

    def recording_part(*args):
        try:
            return real_part(*args)
        except BaseException as exc:
            ended.append(type(exc))
            raise

    def failing_paper(*args, **kwargs):
        assert in_kernels.wait(300), "the simulated part never started a kernel"
        raise error

    monkeypatch.setattr(continued, "simulated_part", recording_part)
    monkeypatch.setattr(matching, "index_of_system", failing_paper)
    monkeypatch.setattr(matching, "_beside_allowed", lambda m: True)
    with pytest.raises(type(error)):
        matching.matching_index(load_preset("turnout-soft"))
    assert not _running_beside()
    assert ended == [Stopped]
