"""Accuracy figures tracked over commits (asv ``track_*``), from ``benchmarks/figures.py``.

Each class computes its figures once (``setup_cache``) for a small fixed seed set; the same
functions feed the accuracy gate (``benchmarks/gate.py``, a reduced set) and the README.
"""

import figures

_REFERENCE_SAMPLES = {"online": 30_000, "eria": 30_000}


def _nan(value):
    return float("nan") if value is None else float(value)


class ReferenceStage:
    """Parameter error and held-out RMS per method, reference stage, 1 nm, seeds 0-2."""

    timeout = 900
    params = list(figures.METHODS)
    param_names = ["method"]
    seeds = (0, 1, 2)

    def setup_cache(self):
        return {m: [figures.reference_identification(m, seed=s,
                                                     samples=_REFERENCE_SAMPLES.get(m, 6_000))
                    for s in self.seeds] for m in figures.METHODS}

    def track_param_error(self, rows, method):
        """Median max relative parameter error (NaN for the PI sandwich)."""
        return _median([r["final_err"] for r in rows[method]])

    track_param_error.unit = "relative"

    def track_heldout_rms(self, rows, method):
        """Median held-out RMS, nm (NaN when a model is unstable)."""
        return _median([r.get("val_rms") for r in rows[method]]) * 1e3

    track_heldout_rms.unit = "nm"


def _median(values):
    import numpy as np

    return float("nan") if any(v is None for v in values) else float(np.median(values))


class AsMeasured:
    """Held-out RMS and parameter error on ``hystid.testing.as_measured_suite`` (seed 0)."""

    timeout = 1800
    params = (["batch", "online", "ekf"], list(figures.AS_MEASURED))
    param_names = ["method", "case"]

    def setup_cache(self):
        return {(m, c): figures.as_measured(m, c) for m in self.params[0]
                for c in self.params[1]}

    def track_heldout_rms(self, rows, method, case):
        """Held-out RMS in the record's output unit."""
        return rows[method, case]["heldout_rms"]

    track_heldout_rms.unit = "output unit"

    def track_heldout_vs_linear(self, rows, method, case):
        """Held-out RMS as a share of the linear baseline's (below 1: the model helps)."""
        r = rows[method, case]
        return r["heldout_rms"] / r["linear"]

    track_heldout_vs_linear.unit = "ratio"

    def track_param_error(self, rows, method, case):
        """Max relative parameter error (NaN where the truth is not known in the units)."""
        return _nan(rows[method, case]["param_err"])

    track_param_error.unit = "relative"


class WrongBasin:
    """On-line start-up over seeds 0-4 x 0/1/10 nm x 2 simulators."""

    timeout = 900

    def setup_cache(self):
        return figures.wrong_basin(range(5))

    def track_wrong_basin_rate(self, result):
        return result["rate"]

    track_wrong_basin_rate.unit = "share"

    def track_silent_wrong_basin_rate(self, result):
        return result["silent_rate"]

    track_silent_wrong_basin_rate.unit = "share"


class WithheldEffects:
    """Blind diagnosis of withheld effects, 4 + 4 cases and 2 clean records per source."""

    timeout = 3600
    params = ["in-form", "cross-form"]
    param_names = ["source"]

    def setup_cache(self):
        return figures.withheld_effects(in_form=4, cross_form=4, clean=2)

    def track_top1(self, result, source):
        return _nan(result[source]["top1_accuracy"])

    track_top1.unit = "share"

    def track_false_acceptance(self, result, source):
        return _nan(result[source]["false_acceptance_clean"])

    track_false_acceptance.unit = "share"

    def track_wrong_acceptance(self, result, source):
        return _nan(result[source]["wrong_acceptance"])

    track_wrong_acceptance.unit = "share"


class Tracking:
    """What the feed-forward inverse of an identified model cuts off the tracking error."""

    timeout = 600
    params = ["triangle 10 Hz", "triangle 50 Hz", "sine 50 Hz"]
    param_names = ["scan"]

    def setup_cache(self):
        return {p: figures.tracking_cut(p.split()[0], float(p.split()[1])) for p in self.params}

    def track_tracking_error_cut(self, result, scan):
        """Max tracking error without / with the inverse."""
        return result[scan]["cut"]

    track_tracking_error_cut.unit = "ratio"
