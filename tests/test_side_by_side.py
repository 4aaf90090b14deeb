"""The model choice's fits side by side in threads, and the PI fit's slow-branch polish ended
once it stalls: the same models, in less time.

Records from ``hystid.testing``'s stage-A look-alike (Bouc-Wen hysteresis and a 740 Hz mode,
not a member's form) and, where present, measured stage A.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import quiet

from hystid.baselines import compare
from hystid.identify import pi_batch
from hystid.identify.members import PI_NFEV, member, select_member
from hystid.records import load_record
from hystid.testing import stage_a_like
from hystid.threads import run_side_by_side, worker_count

STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


def test_worker_count_takes_whole_numbers_and_names_the_option():
    assert worker_count(3) == 3
    assert worker_count(None) >= 1
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="workers"):
            worker_count(bad)


def test_calls_side_by_side_keep_their_order_and_raise_the_first_error():
    seen = set()

    def call(i):
        def run():
            seen.add(threading.current_thread().name)
            return i * i
        return run

    assert run_side_by_side([call(i) for i in range(5)], workers=2) == [0, 1, 4, 9, 16]
    assert run_side_by_side([call(i) for i in range(3)], workers=1) == [0, 1, 4]
    with pytest.raises(ZeroDivisionError):
        run_side_by_side([call(1), lambda: 1 / 0], workers=2)


def test_the_choice_is_the_same_on_one_thread_or_two():
    rec = stage_a_like("prbn", seconds=0.6, rest_seconds=0.2, seed=4)
    one = quiet(select_member, rec, workers=1)
    two = quiet(select_member, rec, workers=2)
    assert one.info["model"] == two.info["model"]
    np.testing.assert_array_equal(one.model.theta, two.model.theta)
    for a, b in zip(one.info["member_selection"]["candidates"],
                    two.info["member_selection"]["candidates"], strict=True):
        assert a["member"] == b["member"] and a["heldout_rms"] == b["heldout_rms"]
    assert one.info["member_selection"]["baselines"] == two.info["member_selection"]["baselines"]


def test_the_stall_check_stops_a_crawl_and_not_a_descent():
    check = pi_batch._stall_check(3)
    for cost in (10.0, 8.0, 6.0, 4.0, 2.0, 1.0):  # falling by far more than the share
        check(type("R", (), {"cost": cost})())
    crawl = pi_batch._stall_check(3)
    with pytest.raises(StopIteration):
        for cost in (1.0, 0.99995, 0.9999, 0.99985, 0.9998):
            crawl(type("R", (), {"cost": cost})())


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A records absent ({STAGE_A})")
def test_a_stalled_slow_branch_polish_ends_early_and_loses_nothing(monkeypatch):
    """On measured stage A's triangle the slow branch's polish crawled on for all of its 200
    evaluations and took 0.1 % off the cost: ended when it stalls, the fit is within 0.1 % of
    that residual and as good held out."""
    train, held = (load_record(STAGE_A / f"tri50_{i}.csv") for i in (1, 2))
    stalled = quiet(member("pi-stage").fit, train)
    monkeypatch.setattr(pi_batch, "STALL_SHARE", 0.0)  # never stalls: the full polish
    full = quiet(member("pi-stage").fit, train)
    assert full.info["start"] == stalled.info["start"] == pi_batch.SLOW_START
    assert full.info["nfev"] == pi_batch.SLOW_START_NFEV * PI_NFEV
    assert stalled.info["nfev"] <= 0.6 * full.info["nfev"]
    assert stalled.info["rms_residual"] <= 1.001 * full.info["rms_residual"]
    a, b = (quiet(compare, r.model, train, [held]).rows[0] for r in (stalled, full))
    assert a["model"] <= b["model"] + 1e-3 and a["model"] < 0.5 * a["linear"]


def test_calls_side_by_side_see_the_caller_s_context():
    from hystid.identify.output_jumps import CHECKING

    token = CHECKING.set(False)  # as inside an identify() call: the fits it starts are nested
    try:
        assert run_side_by_side([CHECKING.get, CHECKING.get], workers=2) == [False, False]
    finally:
        CHECKING.reset(token)


class _Crawl:
    """A stand-in PI member whose fit takes ``steps`` evaluations, each a cancellation point."""

    kind = "pi"

    def __init__(self, name: str, steps: int) -> None:
        self.name, self.steps, self.done = name, steps, 0

    def fit(self, record, **settings):
        from hystid.threads import check_cancelled

        for _ in range(self.steps):
            check_cancelled()
            self.done += 1
            threading.Event().wait(0.002)
        return ("fitted", self.name, settings)


def test_a_fit_started_ahead_is_cancelled_when_another_is_chosen():
    from hystid.identify.members import _AheadFits
    from hystid.threads import side_by_side

    kept, dropped = _Crawl("kept", 20), _Crawl("dropped", 5000)
    with side_by_side(2) as jobs:
        ahead = _AheadFits(jobs, [kept, dropped], None, {"offset": 1.0})
        while dropped.done == 0:
            threading.Event().wait(0.001)
        ahead.keep_only("kept")
        assert ahead.result("kept").result() == ("fitted", "kept", {"offset": 1.0})
        assert ahead.result("dropped") is None  # cancelled: the choice fits it afresh
        assert ahead.futures["dropped"].result() is None
    assert dropped.done < dropped.steps  # it stopped, it did not run on to its end


def test_a_cancelled_fit_is_not_taken_for_a_failure_on_the_way():
    from hystid.threads import Cancelled, cancellable, check_cancelled

    event = threading.Event()

    def fit_with_a_broad_except():
        try:
            event.set()
            check_cancelled()
        except Exception:  # a fit's own error handling must not swallow the cancellation
            return "swallowed"
        return "finished"

    assert cancellable(fit_with_a_broad_except, event)() is None
    check_cancelled()  # outside a cancellable call nothing is cancelled
    assert not issubclass(Cancelled, Exception)


@pytest.mark.skipif(not (STAGE_A / "prbn_1.csv").exists(),
                    reason="needs measured stage A in ../shared/data/real/stageA")
def test_the_model_fitted_ahead_is_the_model_fitted_after_the_choice():
    # on prbn_1 the choice takes pi-stage: on two threads its whole-record fit from its own
    # starts runs ahead of the choice, on one after it; the model is the same to the last digit
    rec = load_record(STAGE_A / "prbn_1.csv")
    one = quiet(select_member, rec, workers=1)
    two = quiet(select_member, rec, workers=2)
    assert one.info["model"] == two.info["model"] == "pi-stage"
    np.testing.assert_array_equal(one.model.theta, two.model.theta)
    assert one.info["rms_residual"] == two.info["rms_residual"]
