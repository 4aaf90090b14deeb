"""The diagnosis side by side: its refits, screen and member fits in threads.

Records from hystid.testing's independent stage simulator (a pure dead time written apart from
the diagnosis' delay form, and a Bouc-Wen stage). The threads must not change the diagnosis:
with the time budget off, one thread, two or four give the same result to the last bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_final import FS, _records

from hystid.diagnose import diagnose
from hystid.diagnose.final_model import final_model
from hystid.diagnose.refit import FitData, _distinct, refit
from hystid.diagnose.screen import zero_vector
from hystid.errors import DiagnosisError
from hystid.reference import reference_model


def _figures(res) -> dict:
    """Everything a diagnosis decides and every figure it gives, per round and candidate."""
    rounds = [{n: (c["status"], c.get("rms_val_after"), c.get("p_value"))
               for n, c in r["candidates"].items()} | {"accepted": r["accepted"]}
              for r in res.rounds]
    return {"accepted": list(res.accepted), "final": res.final["rms_val"],
            "phi": res.final["effects"], "rounds": rounds,
            "nominal": res.nominal["rms_val"]}


def test_one_thread_two_or_four_give_the_same_diagnosis():
    """A pure dead time (the refit with several joint starts, the screen, the drift beside the
    screen, a member beside the rounds): the same decisions and figures, bit for bit, and the
    same member model."""
    train, val = _records("delay", "pure", 4.0, seed=11)
    runs = [diagnose(train, val, budget_factor=None, members=("pi-stage",), workers=w,
                     progress=False) for w in (1, 2, 4)]
    assert _figures(runs[0]) == _figures(runs[1]) == _figures(runs[2])
    assert runs[0].accepted, "the dead time should be found (the comparison would be empty)"
    a, b, c = (r.members["pi-stage"] for r in runs)
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_array_equal(a.theta, c.theta)


def test_members_fitted_beside_the_rounds_are_the_final_model_s():
    """A Bouc-Wen stage: the member the diagnosis fitted beside its rounds is the one the final
    model scores (no second fit), with the figures a fit after the rounds gives."""
    train, val = _records(None, None, None, seed=3, hysteresis="bouc_wen")
    res = diagnose(train, val, members=("pi-stage",), workers=2, progress=False)
    lines: list[str] = []
    beside = final_model(res, train, [val], progress=lines.append)
    assert not any("fitting" in line for line in lines), lines
    res.members = {}
    after = final_model(res, train, [val], progress=lines.append)
    assert any("fitting the pi-stage member" in line for line in lines)
    assert [r["mean_rms"] for r in beside.rows] == [r["mean_rms"] for r in after.rows]
    assert beside.chosen == after.chosen


@pytest.mark.parametrize("option, value, said", [
    ("workers", 0, "workers"), ("workers", 1.5, "workers"), ("workers", True, "workers"),
    ("members", ("pi-stage", "nope"), "members"),
])
def test_bad_threads_or_members_are_refused_before_any_fit(option, value, said):
    train, val = _records(None, None, None, seed=5)
    with pytest.raises(DiagnosisError, match=said):
        diagnose(train, val, progress=False, **{option: value})


def test_a_minimum_found_twice_is_one_joint_start():
    """Effect-only solutions that agree within the tolerance are one start: the refit from a
    start given twice is the refit from it given once (its joint stage is not run twice)."""
    kept = _distinct([np.array([2.0, 0.0]), np.array([2.0005, 1.0]), np.array([3.0, 0.0])],
                     [0])
    assert [k[0] for k in kept] == [2.0, 3.0]
    train, _ = _records("delay", "pure", 3.0, seed=7)
    model = reference_model(FS)
    data = FitData(train.u - train.u[0], train.y - train.y[0], FS)
    start = zero_vector()
    starts = []
    for d in (3.0, 3.0, 6.0):
        s = start.copy()
        s[7] = d
        starts.append(s)
    twice = refit(model, data, ["delay"], starts, joint_starts=3)
    once = refit(model, data, ["delay"], [starts[0], starts[2]], joint_starts=2)
    np.testing.assert_array_equal(twice.theta, once.theta)
    np.testing.assert_array_equal(twice.phi, once.phi)
    assert twice.ok


def test_an_error_in_a_refit_thread_reaches_the_caller(monkeypatch):
    """A refit that raises in its thread raises from ``diagnose`` itself (the work still
    queued is dropped), not a hang or a result without it."""
    import hystid.diagnose.rounds as rounds

    real = rounds.refit

    def broken(model, data, active, *args, **kwargs):
        if active and active[-1] == "creep_2tau":
            raise RuntimeError("creep_2tau refit broke")
        return real(model, data, active, *args, **kwargs)

    monkeypatch.setattr(rounds, "refit", broken)
    train, val = _records(None, None, None, seed=2)
    with pytest.raises(RuntimeError, match="creep_2tau refit broke"):
        diagnose(train, val, budget_factor=None, effects=("saturation", "creep"), workers=2,
                 refit_all=True,
                 progress=False)


def test_a_member_fit_that_fails_beside_the_rounds_is_said_and_left_out(monkeypatch):
    """The member's fit fails in its thread: the diagnosis says so and goes on; the final
    model then fits it itself (and would report that failure as its own)."""
    import hystid.diagnose.diagnosis as diagnosis

    def failing(name, record):
        raise ValueError("no fit today")

    monkeypatch.setattr(diagnosis, "fit_member", failing)
    train, val = _records(None, None, None, seed=4)
    lines: list[str] = []
    res = diagnose(train, val, members=("pi-stage",), workers=2, progress=lines.append)
    assert res.members == {}
    assert any("pi-stage member's fit failed: no fit today" in line for line in lines)
    final = final_model(res, train, [val])
    assert "pi-stage" in [r["candidate"] for r in final.rows]


def test_progress_is_called_from_the_calling_thread_only():
    """A progress callback (a GUI's, say) is never called from a worker thread, though the
    drift's refit, the screen and the refits run there."""
    import threading

    train, val = _records("drift", None, 1.0, seed=5)
    seen: set[int] = set()
    lines: list[str] = []

    def note(line: str) -> None:
        seen.add(threading.get_ident())
        lines.append(line)

    diagnose(train, val, members=("pi-stage",), workers=2, progress=note)
    assert seen == {threading.get_ident()}
    assert any("own drift" in line for line in lines)
    assert any("refitting" in line for line in lines)


@pytest.mark.parametrize("workers", [1, 2])
def test_members_start_beside_the_nominal_fit_when_there_are_threads_to_spare(workers):
    """The member fits do not depend on the nominal model: on two threads they start before
    the nominal fit, which runs in the calling thread; on one they queue behind the first
    round's refits. The diagnosis is the same (``test_one_thread_two_or_four...``)."""
    train, val = _records(None, None, None, seed=4)
    lines: list[str] = []
    diagnose(train, val, members=("pi-stage",), workers=workers, progress=lines.append)
    member = next(i for i, line in enumerate(lines) if "fitting the pi-stage member" in line)
    nominal = next(i for i, line in enumerate(lines) if "identifying the nominal" in line)
    assert (member < nominal) == (workers > 1)


def test_an_error_in_the_nominal_fit_does_not_wait_for_the_members(monkeypatch):
    """The nominal fit fails while a member is fitted beside it: the member's fit is cancelled
    at its next evaluation and the error reaches the caller (not after the member's fit)."""
    import threading

    import hystid.diagnose.diagnosis as diagnosis
    from hystid.threads import Cancelled, check_cancelled

    started, ended = threading.Event(), []

    def crawling(name, record):
        started.set()
        try:
            for _ in range(30_000):  # 60 s unless cancelled
                check_cancelled()
                threading.Event().wait(0.002)
        except Cancelled:
            ended.append("cancelled")
            raise
        ended.append("ran to its end")

    def failing(*args, **kwargs):
        started.wait(30)
        raise RuntimeError("nominal fit broke")

    monkeypatch.setattr(diagnosis, "fit_member", crawling)
    monkeypatch.setattr(diagnosis, "_identify", failing)
    train, val = _records(None, None, None, seed=4)
    with pytest.raises(RuntimeError, match="nominal fit broke"):
        diagnose(train, val, members=("pi-stage",), workers=2, progress=False)
    assert ended == ["cancelled"]


def test_the_nominal_fit_says_how_far_it_is():
    """The nominal fit (a minute or more on a long measured record) is not silent: a line as
    each of its starts is screened and polished, between the diagnosis' own lines."""
    train, val = _records(None, None, None, seed=4)
    lines: list[str] = []
    diagnose(train, val, max_rounds=1, progress=lines.append)
    first = next(i for i, line in enumerate(lines) if "identifying the nominal" in line)
    last = next(i for i, line in enumerate(lines) if line.startswith("nominal model:"))
    inside = lines[first + 1:last]
    assert any(line.startswith("batch fit of") and "start 1 of" in line for line in inside)
    assert any("polishing the best start" in line for line in inside)
