"""Sim-to-real gap diagnosis: where the error lies, which unmodelled effect causes it, how far
it shrinks once that effect is in the model.

* :func:`diagnose` -- the whole diagnosis; returns a :class:`DiagnosisResult`
  (``to_dict()`` is the JSON report, ``plot(out_dir)`` the figures).
* :mod:`.where` -- localisation of the error (time, frequency, zones, branches, correlation
  tests, noise floor).
* :mod:`.effects` -- the candidate effects (``creep``, ``drift``, ``extra_mode``, ``delay``,
  ``asymmetry``, ``slew_limit``) as augmentations of the sandwich; :func:`simulate_with_effect`.
* :mod:`.screen` -- screening and the held-out significance test; :mod:`.refit` -- the refits.
* :mod:`.report` -- summary and figures; :mod:`.command` -- ``hystid diagnose``.
"""

from .diagnosis import DiagnosisError, DiagnosisResult, EffectOutcome, diagnose
from .effects import EFFECT_NAMES, EFFECTS, AugmentedSandwich, simulate_with_effect
from .where import Where, localise, noise_floor

__all__ = [
    "EFFECTS",
    "EFFECT_NAMES",
    "AugmentedSandwich",
    "DiagnosisError",
    "DiagnosisResult",
    "EffectOutcome",
    "Where",
    "diagnose",
    "localise",
    "noise_floor",
    "simulate_with_effect",
]
