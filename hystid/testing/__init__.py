"""Independent stage simulators for tests and benchmarks.

The generators here are written from the paper's equations and from physics, independently of the
identification code, so that methods can be tested on data they do not share assumptions with:

- :mod:`hystid.testing.stages`: the sandwich L1 -> H -> L2 with Duhem, Bouc-Wen, Preisach or
  Maxwell-slip hysteresis, the paper's stage and its excitation;
- :mod:`hystid.testing.effects`: unmodelled effects (creep, drift, delay, asymmetry, slew limit,
  saturation, an extra mode), each in two or more forms, and :func:`simulate_stage`;
- :mod:`hystid.testing.measured`: "as measured" transformations of records and look-alikes of
  two measured stages, and the suite of named records the identification tests run on.
"""

from .effects import EFFECTS, EffectForm, list_effects, simulate_stage
from .measured import (
    UNIT_FACTORS,
    as_measured_suite,
    coloured_variations,
    crop_start,
    hold_then_excite,
    record_from,
    repeats,
    replace_name,
    simulate_at_rate,
    stage_a,
    stage_a_like,
    stage_b,
    stage_b_like,
    with_burst,
    with_clipping,
    with_end_glitch,
    with_noise,
    with_offset,
    with_outliers,
    with_units,
)
from .stages import (
    PAPER,
    BoucWen,
    Duhem,
    Hysteresis,
    Linear,
    MaxwellSlip,
    Preisach,
    SandwichStage,
    continuous_linear,
    make_hysteresis,
    paper_excitation,
    paper_like_stage,
    paper_stage,
    paper_stage_loop,
    prbs,
)

__all__ = [
    "EFFECTS",
    "EffectForm",
    "list_effects",
    "simulate_stage",
    "PAPER",
    "UNIT_FACTORS",
    "BoucWen",
    "Duhem",
    "Hysteresis",
    "Linear",
    "MaxwellSlip",
    "Preisach",
    "SandwichStage",
    "as_measured_suite",
    "coloured_variations",
    "continuous_linear",
    "crop_start",
    "hold_then_excite",
    "make_hysteresis",
    "paper_excitation",
    "paper_like_stage",
    "paper_stage",
    "paper_stage_loop",
    "prbs",
    "record_from",
    "repeats",
    "replace_name",
    "simulate_at_rate",
    "stage_a",
    "stage_a_like",
    "stage_b",
    "stage_b_like",
    "with_burst",
    "with_clipping",
    "with_end_glitch",
    "with_noise",
    "with_offset",
    "with_outliers",
    "with_units",
]
