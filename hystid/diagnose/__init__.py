"""Sim-to-real gap diagnosis: where the error lies, which unmodelled effect causes it, how far
it shrinks once that effect is in the model.

* :func:`diagnose` -- the whole diagnosis; returns a :class:`DiagnosisResult`
  (``to_dict()`` is the JSON report, ``plot(out_dir)`` the figures).
* :mod:`.where` -- localisation of the error (time, frequency, zones, branches, correlation
  tests, noise floor).
* :mod:`.effects` -- the candidate effects, families of forms (``creep``: one lag, two lags,
  logarithmic; ``asymmetry``: by the direction of w1 or of the input, by level, an offset;
  ``extra_mode``: in parallel or in series; ``drift``, ``delay``, ``slew_limit``,
  ``saturation``) as augmentations of the sandwich; :func:`simulate_with_effect`.
* :mod:`.structure` -- a dead time of several samples as the structure change ``q1 + d``.
* :mod:`.screen` -- screening and the held-out significance test; :mod:`.refit` -- the refits.
* :mod:`.report` -- summary and figures; ``hystid diagnose`` is :mod:`hystid.cli.diagnose`.
"""

import importlib

# the submodules load on first use: importing one of them (the command line reads .screen, say)
# loads none of the others
_HOME = {
    "DiagnosisError": "diagnosis", "DiagnosisResult": "diagnosis", "EffectOutcome": "diagnosis",
    "diagnose": "diagnosis", "EFFECT_NAMES": "effects", "EFFECTS": "effects",
    "FAMILIES": "effects", "AugmentedSandwich": "effects", "family_of": "effects",
    "simulate_with_effect": "effects", "Where": "where", "localise": "where",
    "noise_floor": "where",
}

__all__ = [
    "EFFECTS",
    "EFFECT_NAMES",
    "FAMILIES",
    "AugmentedSandwich",
    "DiagnosisError",
    "DiagnosisResult",
    "EffectOutcome",
    "Where",
    "diagnose",
    "family_of",
    "localise",
    "noise_floor",
    "simulate_with_effect",
]


def __getattr__(name: str):
    if name in _HOME:
        return getattr(importlib.import_module(f".{_HOME[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_HOME])
