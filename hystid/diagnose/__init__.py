"""Sim-to-real gap diagnosis: where the error lies, which unmodelled effect causes it, how far
it shrinks once that effect is in the model.

* :func:`diagnose` -- the whole diagnosis; returns a :class:`DiagnosisResult`
  (``to_dict()`` is the JSON report, ``plot(out_dir)`` the figures).
* :mod:`.where` -- localisation of the error (time, frequency, zones, branches, correlation
  tests, noise floor).
* :mod:`.effects` -- the candidate effects, families of forms (``creep``: one lag, two lags,
  logarithmic; ``asymmetry``: by direction, by level, an offset; ``extra_mode``: in parallel or
  in series; ``drift``, ``delay``, ``slew_limit``, ``saturation``) as augmentations of the
  sandwich; :func:`simulate_with_effect`.
* :mod:`.screen` -- screening and the held-out significance test; :mod:`.refit` -- the refits.
* :mod:`.report` -- summary and figures; :mod:`.command` -- ``hystid diagnose``.
"""

from .diagnosis import DiagnosisError, DiagnosisResult, EffectOutcome, diagnose
from .effects import (
    EFFECT_NAMES,
    EFFECTS,
    FAMILIES,
    AugmentedSandwich,
    family_of,
    simulate_with_effect,
)
from .where import Where, localise, noise_floor

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
