"""``obsfmuRound`` (fmus/master/round.py, fmus/native/loader.c): the master's Gauss-Seidel round in one call of an
obsfmu binary is the Python round, bit for bit -- linear and held coupling, a ramped start, the adaptive
master's rollbacks -- and a failing member is named as before."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from obsfmu.fmus.master import Component, SimulationError, Session, System
from obsfmu.fmus.master.round import NativeRound, Stepper
from obsfmu.fmus.scenarios import ensure_fmus, get

ERROR = 3


def system(scenario, fmus, start=None):
    start = start or {}
    return System([Component(i, fmus[m], {**s, **start.get(i, {})}) for i, m, s in scenario.components],
                  list(scenario.connections))


def counted_rounds(patch) -> list:
    """Patch :meth:`NativeRound.run` to count its calls in the returned list."""
    calls, run = [], NativeRound.run

    def counted(self, *args):
        calls.append(1)
        return run(self, *args)

    patch.setattr(NativeRound, "run", counted)
    return calls


def runs(session, monkeypatch, native: bool, **settings):
    """``session.run(**settings)`` with the round in one call (``native``) or the Python round; with the
    number of rounds made in one call."""
    with monkeypatch.context() as patch:
        calls = counted_rounds(patch)
        if not native:
            patch.setattr(NativeRound, "of", classmethod(lambda cls, *args: None))
        return session.run(**settings), len(calls)


@pytest.mark.parametrize("name, settings", [
    ("ship", dict(coupling="linear")),
    ("ship", dict(coupling="hold")),
    ("ship", dict(coupling="linear", ramp=3)),
    ("ship", dict(order="adaptive", tolerance=1e-4)),
    ("ltv-ls-bounded", dict(coupling="linear")),      # three FMUs, 31 outputs, a feedback loop
])
def test_the_round_in_one_call_is_the_python_round(build_dir, monkeypatch, name, settings):
    scenario = get(name)
    fmus = ensure_fmus(scenario, build_dir)
    steps = 40
    settings = dict(stop_time=steps * scenario.step, step=scenario.step, **settings)
    with Session(system(scenario, fmus, {"observer": {"x_hat0[1]": 0.01}} if name == "ship" else None),
                 echo_log=False) as session:
        fast, rounds = runs(session, monkeypatch, True, **settings)
        slow, none = runs(session, monkeypatch, False, **settings)
    expected = steps + settings.get("ramp", 0)     # the ramp splits the first step into ramp + 1
    assert none == 0 and (rounds >= 3 if settings.get("order") == "adaptive" else rounds == expected)
    assert np.array_equal(fast.time, slow.time)
    assert np.array_equal(fast.values, slow.values), np.max(np.abs(fast.values - slow.values))


def test_a_failing_member_is_named(ship_fmus, faulty_fmus, monkeypatch):
    """The ship's FMUs and, last, a plant whose step fails inside the slave (tests/faulty_user_function.py)."""
    scenario = get("ship")
    components = system(scenario, ship_fmus).components + [Component("faulty", faulty_fmus[2], {"x0[1]": 0.0, "u": 0.0})]
    with Session(System(components, list(scenario.connections)), echo_log=False) as session:
        with pytest.raises(SimulationError, match=r"faulty: doStep\(t=0, h=0.001\) with its inputs failed "
                                                  r"\(status 3 \(error\)\); FMU says: .*"):
            calls = counted_rounds(monkeypatch)
            session.run(0.01, 1e-3)
    assert calls == [1]


def test_bad_links_are_refused_before_any_step(ship_fmus):
    """An input linked past the end of the outputs: fmi2Error naming the member, no FMU stepped."""
    with Session(system(get("ship"), ship_fmus), echo_log=False) as session:
        session.run(0.002, 1e-3)
        stepper = Stepper(session.instances, session.logger, jacobi=False, linear=True)
        native = stepper.native
        assert native is not None
        member = list(session.instances.values()).index(next(i for i in session.instances.values() if i.input_vrs))
        wrong = np.full(len(native.instances[member].input_vrs), stepper.live.size, dtype=np.uintp)
        native._members[member].source = wrong.ctypes.data
        live = stepper.live.copy()
        failed = ctypes.c_size_t(99)
        assert native.function(native._address, 0.0, 1e-3, ctypes.addressof(failed)) == ERROR
        assert failed.value == member
        assert np.array_equal(stepper.live, live)
        assert native.function(native._address, 0.0, -1.0, ctypes.addressof(failed)) == ERROR   # h <= 0
        assert native.function(None, 0.0, 1e-3, ctypes.addressof(failed)) == ERROR


@pytest.mark.parametrize("fmi_version, order, native", [(2, "gauss-seidel", True), (2, "jacobi", False),
                                                         (3, "gauss-seidel", False)])
def test_the_round_is_chosen_once_per_run(build_dir, fmi_version, order, native):
    """The round in one call serves Gauss-Seidel runs of obsfmu FMI 2.0 FMUs; Jacobi runs and FMI 3.0 FMUs
    (no one-call step) take the Python round, chosen when the stepper is made."""
    scenario = get("ship")
    fmus = ensure_fmus(scenario, build_dir, fmi_version=fmi_version)
    with Session(system(scenario, fmus), echo_log=False) as session:
        stepper = Stepper(session.instances, session.logger, jacobi=order == "jacobi", linear=True)
        assert (stepper.native is not None) == native
        assert all(inst.batched for inst in session.instances.values()) == (fmi_version == 2)
