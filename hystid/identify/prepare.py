"""A record as it comes, made ready for identification.

Measured records do not look like the reference stage: the sensor's zero is not the stage's,
the stage rests at some input level before the excitation (or is already moving), the units
may be V or kV, um or m, and there are outliers, clipped sensors and generators that wrap
their last sample round. :func:`prepare` turns a :class:`~hystid.records.Record` into a
:class:`Prepared` problem, in named steps:

1. :func:`check_excitation` -- refuse a record that cannot identify a stage (a constant input,
   a single step, an output equal to the input);
2. :func:`rest_level` -- the input level the stage rests at (the leading constant segment, or
   the first sample), and whether the record starts at rest;
3. :func:`scales` -- robust input and output scales, so that the fit runs on numbers of order
   one whatever the units (quantiles scale exactly with the units, so the identified model's
   output does not depend on them);
4. :func:`bad_samples` -- outliers (spikes against a running median, far values against the
   output's spread) and a saturated sensor, left out of the cost with a note;
5. :func:`burn_in` -- for a record that does not start at rest, the samples until the input
   has swept its range once are simulated but not fitted: the stage's state before the record
   began is unknown, and the Duhem block forgets it as ``w1`` moves. The same holds after an
   isolated input jump (many times the slew the input otherwise holds: a step out of rest, a
   generator wrapping its last sample round): what it excites lies outside the input envelope
   the model is identified for.

The sensor offset is not removed here: it is a parameter of every fit (``y0``), started from
the output's level at rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import IdentificationDataError
from ..operating import Envelope
from ..records import Record
from ..records_checks import burst_spans, one_rate_note, record_warnings
from ..signals import kept_samples

__all__ = ["IdentificationDataError", "Prepared", "bad_samples", "burn_in", "check_excitation",
           "held_out_from", "input_glitches", "prepare", "rest_level", "scales",
           "shows_rest", "without_input_glitches"]

#: Samples of a leading constant segment needed to call a record "at rest".
REST_SAMPLES = 10
#: A spike is a sample this many robust standard deviations off the running median.
SPIKE_SIGMAS = 10.0
#: A far value is this many output spreads (2 % to 98 % quantiles) away from the median.
FAR_SPREADS = 3.0
#: An input step this many times the envelope's slew is a jump (out of rest, a wrapped
#: sample): what it excites is outside the envelope the model is identified for.
JUMP_SLEWS = 10.0
#: Share of samples pinned at an extreme for the sensor to count as saturated.
SATURATION_SHARE = 0.005
#: Range of the input's scale (:func:`scales`) a record may have in its own units: the
#: identified parameters scale with powers of it (``alpha / u_scale``, ``f3 y_scale /
#: u_scale**3``), so a record in 1e-300 V divides by a cube that is zero, and one far beyond
#: this range gives numbers a model file does not hold (:data:`hystid.validate.MAX_MAGNITUDE`).
#: Any unit a stage is driven in lies well inside. (The output's scale enters the parameters
#: linearly: an output in 1e-300 um is identified like one in um.)
SCALE_RANGE = (1e-90, 1e90)


@dataclass
class Prepared:
    """A record ready to fit, in normalised units.

    Attributes
    ----------
    record : Record
        The record as given.
    u_rest : float
        Input rest level (record units).
    u_scale, y_scale : float
        Input and output scales: the fit sees ``un = (u - u_rest) / u_scale`` and
        ``yn = (y - y_ref) / y_scale``.
    y_ref : float
        Output reference (the output at rest, or the median output).
    un, yn : ndarray
        The normalised input and output.
    weight : ndarray of bool
        Samples in the cost.
    at_rest : bool
        Whether the record starts at rest (a leading constant input segment).
    skip : int
        Leading samples left out of the cost (burn-in).
    envelope : Envelope
        The input envelope over the fitted samples (record units).
    notes : list of str
        What was found and done (outliers, saturation, not at rest, a wrapped last sample).
    held : ndarray of bool or None
        Samples left out at the caller's request (``left_out``: a held-out block), which no
        step of a fit may read; None when there are none.
    """

    record: Record
    u_rest: float
    u_scale: float
    y_ref: float
    y_scale: float
    un: np.ndarray
    yn: np.ndarray
    weight: np.ndarray
    at_rest: bool
    skip: int
    envelope: Envelope
    notes: list[str] = field(default_factory=list)
    held: np.ndarray | None = None

    @property
    def fitted(self) -> slice:
        """The span of samples the fit scores: from the burn-in to the end, less a wrapped last
        sample."""
        n = len(self.weight)
        return slice(self.skip, n - (0 if self.weight[-1] else 1))

    @property
    def y0_start(self) -> float:
        """Start value of the normalised offset: the output at rest (0 by construction)."""
        return 0.0

    def offset(self, y0n: float) -> float:
        """The sensor offset in record units from its normalised value.

        Parameters
        ----------
        y0n : float
            The offset in the fit's normalised output units.

        Returns
        -------
        float
            The offset in the record's output units.
        """
        return float(self.y_ref + self.y_scale * y0n)


def check_excitation(record: Record) -> None:
    """Refuse a record whose input cannot identify a stage.

    Parameters
    ----------
    record : Record
        The record.

    Raises
    ------
    IdentificationDataError
        When ``u`` is constant, takes only two levels with a single transition (a single
        step), or when ``y`` is ``u`` (the same column read twice).
    """
    u, y = record.u, record.y
    where = f"record {record.name!r}"
    span = float(np.ptp(u))
    if span <= 1e-12 * max(float(np.max(np.abs(u))), 1e-300):
        raise IdentificationDataError(
            f"{where}: the input u is constant ({u[0]:.6g}); it does not excite the stage "
            "(expected an input that moves: PRBS, sines, triangles)")
    moves = np.flatnonzero(np.abs(np.diff(u)) > 1e-9 * span)
    if len(moves) <= 1:
        raise IdentificationDataError(
            f"{where}: the input is a single step (it moves once, at sample {moves[0] + 1}); "
            "a step excites neither the loop nor the dynamics enough to identify the stage "
            "(expected an input that moves back and forth)")
    if np.array_equal(u, y):
        raise IdentificationDataError(
            f"{where}: the output y equals the input u sample for sample (the same column read "
            "twice?); expected the measured displacement as y")


def rest_level(u: np.ndarray) -> tuple[float, bool, int]:
    """The input level the stage rests at.

    Parameters
    ----------
    u : ndarray
        Input samples.

    Returns
    -------
    u_rest : float
        Median of the leading constant segment (the first sample when there is none).
    at_rest : bool
        True when the record starts with at least :data:`REST_SAMPLES` constant samples, or
        when its input starts at exactly zero or at an end of its range (a generator ramping
        up from rest; the end of the range is the same test whatever the input's offset, so
        that shifting the input does not change the fit).
    n_lead : int
        Length of the leading constant segment.
    """
    span, n_lead = _lead(u)
    at_end = min(float(u[0] - np.min(u)), float(np.max(u) - u[0])) <= 1e-9 * span
    return (float(np.median(u[:max(n_lead, 1)])), shows_rest(u) or at_end, n_lead)


def shows_rest(u: np.ndarray) -> bool:
    """Whether a record shows its stage at rest before it moves: it starts with at least
    :data:`REST_SAMPLES` constant samples, or at exactly zero (a generator's own zero).

    A start at an end of the input's range without either (which :func:`rest_level` also
    takes as a rest, for the fit) is as well the peak of a sine cut from a longer run: seen
    alone, the input cannot tell them apart.

    Parameters
    ----------
    u : ndarray
        Input samples.

    Returns
    -------
    bool
    """
    span, n_lead = _lead(u)
    return n_lead >= REST_SAMPLES or abs(float(u[0])) <= 1e-12 * span


def _lead(u: np.ndarray) -> tuple[float, int]:
    """The input's span and the length of its leading constant segment."""
    span = float(np.ptp(u))
    moved = np.flatnonzero(np.abs(u - u[0]) > 1e-6 * span)
    return span, int(moved[0]) if len(moved) else len(u)


def _still_output(u: np.ndarray, y: np.ndarray) -> bool:
    """Whether the output sits at one value on most samples while the input moves over them
    (a command read as the output: the columns swapped)."""
    ok = np.isfinite(y)
    if not ok.any():
        return False
    values, counts = np.unique(y[ok], return_counts=True)
    still = ok & (y == values[np.argmax(counts)])
    return bool(still.sum() >= 0.5 * len(y) and np.ptp(u[still]) > 0)


def held_out_from(u: np.ndarray, share: float, stop: int | None = None) -> int:
    """First sample of the held-out end when ``share`` of a record's excitation is held out.

    The leading rest (:func:`rest_level`) stays in the identification part; ``share`` of the
    samples after it, up to ``stop``, is held out. A record resting for a second before one
    second of excitation, with ``share=0.4``, is fitted on its rest and 60 % of its excitation
    (not on its rest and a fifth of its excitation, as a share of all its samples would give).

    Parameters
    ----------
    u : ndarray
        Input samples.
    share : float
        Share of the excitation held out, in [0, 1].
    stop : int, optional
        End of the samples shared out (the record's length by default).

    Returns
    -------
    int
        ``k``: samples ``0..k-1`` identify, ``k..stop-1`` are held out.
    """
    _, at_rest, n_lead = rest_level(u)
    lead = n_lead if at_rest else 0
    stop = len(u) if stop is None else stop
    lead = min(lead, stop)
    return lead + int(round((1.0 - share) * (stop - lead)))


def scales(u: np.ndarray, y: np.ndarray, u_rest: float) -> tuple[float, float, float]:
    """Robust scales of the input about its rest and of the output.

    Quantiles scale exactly with the units, so the normalised record (and the fit) is the same
    in V or kV, um or m.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.
    u_rest : float
        Input rest level.

    Returns
    -------
    u_scale : float
        The 99.9 % quantile of ``|u - u_rest|``.
    y_ref : float
        The median output.
    y_scale : float
        Half the spread between the 2 % and 98 % quantiles of ``y`` (a burst or a clipped
        stretch shorter than 2 % of the record does not move it).
    """
    dev = np.abs(u - u_rest)
    u_scale = float(np.quantile(dev, 0.999)) or float(np.max(dev))
    lo, med, hi = np.quantile(y, [0.02, 0.5, 0.98])
    y_scale = 0.5 * float(hi - lo) or float(np.max(np.abs(y - med))) or 1.0
    return u_scale, float(med), y_scale


#: An input step of more than this many times the input's 99.9 % slew sets the stage ringing:
#: no output spike or burst is looked for in the samples after it (:func:`_input_steps`).
STEP_SLEWS = 3.0


def _input_steps(u: np.ndarray) -> list[tuple[int, int, float]]:
    """``(j, n, size)`` per step of the input inside the record of more than
    :data:`STEP_SLEWS` times its 99.9 % slew (from sample ``j - 1`` to ``j``, ``size`` in
    slews) and the samples after it until the input has travelled half its range
    (:func:`burn_in`). Those of more than :data:`JUMP_SLEWS` are the jumps whose samples after
    them the fit leaves out."""
    du = np.abs(np.diff(u))
    slew = max(float(np.quantile(du, 0.999)) if len(du) else 0.0, 1e-300)
    return [(int(j), burn_in(u[j:], False, sweeps=0.5), float(du[j - 1] / slew))
            for j in np.flatnonzero(du[:-1] > STEP_SLEWS * slew) + 1]


def bad_samples(y: np.ndarray, quiet: np.ndarray | None = None
                ) -> tuple[np.ndarray, list[str]]:
    """Samples of ``y`` that a deterministic model should not be fitted to.

    * far values: more than :data:`FAR_SPREADS` output spreads (2 % to 98 % quantiles) from
      the median (a burst, a sensor glitch of 1e12);
    * spikes: a sample off the mean of its two neighbours by more than :data:`SPIKE_SIGMAS`
      robust standard deviations of that second difference and by more than 5 % of the
      output's spread, while the neighbours agree with each other to a third of that (a
      lightly damped mode's peaks have neighbours that agree, but a far smaller excursion);
    * saturation: runs of samples pinned at the output's minimum or maximum, when they hold
      more than :data:`SATURATION_SHARE` of the record.

    Parameters
    ----------
    y : ndarray
        Output samples.
    quiet : ndarray of bool, optional
        Samples where no spike is looked for: the stage's own transient after an input jump
        (left out of the fit by :func:`prepare`), where a lightly damped mode rings from one
        sample to the next (an independently simulated 1.8 kHz mode at 5 kHz, after a step
        out of rest, was reported as four output spikes on a clean record).

    Returns
    -------
    bad : ndarray of bool
        True for the samples to leave out.
    notes : list of str
        One sentence per kind found.
    """
    notes = []
    lo, med, hi = np.quantile(y, [0.02, 0.5, 0.98])
    spread = max(float(hi - lo), 1e-300)
    far = np.abs(y - med) > FAR_SPREADS * spread
    z = np.pad(np.where(far, med, y), 1, mode="edge")
    local = z[1:-1] - 0.5 * (z[:-2] + z[2:])
    apart = np.abs(z[2:] - z[:-2])
    sigma = 1.4826 * float(np.median(np.abs(local - np.median(local)))) + 1e-300
    spike = ((np.abs(local) > SPIKE_SIGMAS * sigma) & (np.abs(local) > 0.05 * spread)
             & (apart < np.abs(local) / 3.0) & ~far)
    if quiet is not None:
        spike &= ~np.asarray(quiet, bool)
    if far.any():
        notes.append(f"{int(far.sum())} output samples lie far outside the output's range "
                     f"(e.g. {y[far][0]:.4g} at sample {int(np.flatnonzero(far)[0])}); left out "
                     "of the fit")
    if spike.any():
        notes.append(f"{int(spike.sum())} output spikes (first at sample "
                     f"{int(np.flatnonzero(spike)[0])}); left out of the fit")
    good = y[~(far | spike)]
    ymin, ymax = float(np.min(good)), float(np.max(good))
    tol = 1e-9 * max(ymax - ymin, 1e-300)
    pinned = np.zeros(len(y), bool)
    for level, label in ((ymax, "maximum"), (ymin, "minimum")):
        at = (np.abs(y - level) <= tol) & ~(far | spike)
        if at.sum() > SATURATION_SHARE * len(y) and at.sum() > 3:
            pinned |= at
            notes.append(f"the sensor looks saturated: {int(at.sum())} samples "
                         f"({100 * at.mean():.1f} %) sit exactly at the output's {label} "
                         f"{level:.6g}; left out of the fit")
    return far | spike | pinned, notes


#: Longest run of input samples taken for a recording glitch (a stage is not driven that way).
MAX_GLITCH = 3
#: Longest run of the same shape that is said, not mended (:func:`input_glitches`): ten
#: samples of stage A's record at 1e6 V gave a model whose envelope, and so the compensator's
#: default limits, reached 1e6 V without a word.
LONG_EXCURSION = 100


def input_glitches(u: np.ndarray, y: np.ndarray, longer: list[str] | None = None
                   ) -> tuple[list[tuple[int, int]], list[str]]:
    """Runs of input samples that were recorded wrong: the stage never saw them.

    A run of at most :data:`MAX_GLITCH` samples, inside the record, more than
    :data:`FAR_SPREADS` input spreads (2 % to 98 % quantiles) from the median input, or beyond
    the input's 1 % to 99 % quantiles by more than :data:`JUMP_SLEWS` times its slew (99 %
    quantile of its steps: a sample 100 V above the range of a stage driven over 170 V), reached
    by a jump of the input into the run and left by one out of it (each more than
    :data:`JUMP_SLEWS` times its slew or its spread: the turning point of a slow triangle, a
    step of one slew from its neighbours, lies that far beyond the quantiles once a ramp holds
    1 000 samples, and a 10 Hz raster at 20 kHz had every peak interpolated away), while the
    output over the run and the samples after it stays within the spread of its own
    sample-to-sample steps, about its own course (the chord from the sample before the run to
    the end of the window: an output moving steadily is not one that reacts) or about its level
    before the run (an input that really went there would move the stage). A model run through
    such a sample would carry its memory (the hysteresis state, the filters) for the rest of the
    record.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.

    longer : list of str, optional
        Receives one sentence per run of the same shape longer than :data:`MAX_GLITCH`
        samples (at most :data:`LONG_EXCURSION`): not mended, but said.

    Returns
    -------
    runs : list of (int, int)
        ``(first, stop)`` of each run.
    notes : list of str
        One sentence per run.
    """
    lo, med, hi = np.quantile(u, [0.02, 0.5, 0.98])
    spread = max(float(hi - lo), 1e-300)
    q_lo, q_hi = np.quantile(u, [0.01, 0.99])
    slew = float(np.quantile(np.abs(np.diff(u)), 0.99)) if len(u) > 1 else 0.0
    beyond = JUMP_SLEWS * slew if slew > 0 else np.inf  # 99 %: not set by a glitch's own jumps
    far = (np.abs(u - med) > FAR_SPREADS * spread) | (u > q_hi + beyond) | (u < q_lo - beyond)
    runs, notes = [], []
    step = float(np.quantile(np.abs(np.diff(y)), 0.99)) if len(y) > 1 else 0.0
    k = 0
    while k < len(u):
        if not far[k]:
            k += 1
            continue
        stop = k
        while stop < len(u) and far[stop]:
            stop += 1
        inside = k > 0 and stop < len(u)
        jumps = inside and min(abs(u[k] - u[k - 1]), abs(u[stop - 1] - u[stop])) > min(
            beyond, spread)
        if inside and jumps and stop - k <= MAX_GLITCH:
            window = y[k - 1:min(len(y), stop + 5 * MAX_GLITCH)]
            chord = np.linspace(window[0], window[-1], len(window))
            moved = min(np.max(np.abs(window - y[k - 1])), np.max(np.abs(window - chord)))
            if moved <= 3.0 * max(step, 1e-300) * (stop - k + 1):
                runs.append((k, stop))
                notes.append(f"the input reads {u[k]:.4g} at sample {k}"
                             + (f" (to {stop - 1})" if stop - k > 1 else "")
                             + f", {abs(u[k] - med) / spread:.2g} input spreads from its median "
                             f"(the input otherwise spans {q_lo:.4g} to {q_hi:.4g}), "
                             "while the output does not move: a recording glitch; identified "
                             "with the input interpolated over it")
        elif inside and jumps and stop - k <= LONG_EXCURSION and longer is not None:
            longer.append(f"the input reads {u[k]:.4g} at samples {k}..{stop - 1}, "
                          f"{abs(u[k] - med) / spread:.2g} input spreads from its median (the "
                          f"input otherwise spans {q_lo:.4g} to {q_hi:.4g}), for {stop - k} "
                          f"samples: longer than a recording glitch ({MAX_GLITCH} samples at "
                          "most), so it is not mended. If the stage never saw it, crop or mend "
                          "the record: the model is fitted through it, and its input envelope "
                          "(compensate's default limits) reaches it")
        k = stop
    return runs, notes


def without_input_glitches(record: Record) -> tuple[Record, list[str]]:
    """The record with its input glitches (:func:`input_glitches`) interpolated over.

    Parameters
    ----------
    record : Record
        The record as given (left unchanged).

    Returns
    -------
    Record
        The same record when there is no glitch, else a copy with the input mended.
    list of str
        What was mended.
    """
    longer: list[str] = []
    runs, notes = input_glitches(record.u, record.y, longer)
    if not runs:
        return record, longer
    u = np.array(record.u, dtype=float)
    for k, stop in runs:
        u[k:stop] = np.interp(np.arange(k, stop), [k - 1, stop], [u[k - 1], u[stop]])
    return Record(u, record.y.copy(), record.fs, units=dict(record.units),
                  name=record.name), notes + longer


def burn_in(u: np.ndarray, at_rest: bool, limit: float = 0.25, sweeps: float = 2.0) -> int:
    """Leading samples to leave out of the cost of a record that does not start at rest.

    Parameters
    ----------
    u : ndarray
        Input samples.
    at_rest : bool
        Whether the record starts at rest (then nothing is left out).
    limit : float
        Largest share of the record left out.
    sweeps : float
        Travel of the input, in input ranges, that the burn-in waits for.

    Returns
    -------
    int
        The samples until the input has travelled ``sweeps`` times its range (2: down and up
        once), at most ``limit`` of the record.
    """
    if at_rest:
        return 0
    travel = np.cumsum(np.abs(np.diff(u, prepend=u[0])))
    k = int(np.searchsorted(travel, sweeps * float(np.ptp(u))))
    return min(k, int(limit * len(u)))


def _check_scales(record: Record, u_scale: float) -> None:
    """Refuse a record whose input spreads outside :data:`SCALE_RANGE`."""
    low, high = SCALE_RANGE
    if not low <= u_scale <= high:
        unit = record.units.get("u", "")
        raise IdentificationDataError(
            f"record {record.name!r}: the input u spreads over {u_scale:.3g} {unit} (expected "
            f"a spread between {low:g} and {high:g} in the record's units: the parameters "
            "scale with its powers; give the record in other units)")


def prepare(record: Record, *, skip: int | None = None,
            left_out: Sequence[tuple[int, int]] = ()) -> Prepared:
    """Run the preparation steps of this module on a record.

    Parameters
    ----------
    record : Record
        The record as it comes.
    skip : int, optional
        Leading samples to leave out of the cost; by default :func:`burn_in`'s choice.
    left_out : sequence of (int, int)
        Spans ``[first, stop)`` of samples simulated but left out of the cost (a block held
        out to score the fit on, as the model choice does: :mod:`hystid.identify.members`).

    Returns
    -------
    Prepared

    Raises
    ------
    IdentificationDataError
        When the record cannot identify a stage (see :func:`check_excitation`), or its input
        spreads outside :data:`SCALE_RANGE`.
    """
    check_excitation(record)
    u, y = record.u, record.y
    u_rest, at_rest, n_lead = rest_level(u)
    kept = kept_samples(len(u), left_out)
    u_scale, y_med, y_scale = scales(u, y[kept], u_rest)
    _check_scales(record, u_scale)
    steps = _input_steps(u)
    jumps = [(j, n) for j, n, size in steps if size > JUMP_SLEWS]
    transient = np.zeros(len(u), bool)  # the stage's own transient after an input step
    for j, n, _ in steps:
        transient[j:j + n] = True
    bad, notes = bad_samples(y, quiet=transient)
    notes += record_warnings(u, y, record.fs, quiet=transient) + one_rate_note(u[n_lead:],
                                                                               record.fs)
    for first, stop in burst_spans(u, y, quiet=transient):
        bad[first:stop] = True
    y_ref = float(np.median(y[:n_lead][~bad[:n_lead]])) if at_rest and (~bad[:n_lead]).any() \
        else y_med
    if not at_rest:
        notes.append("the record does not start at rest (no leading constant input); the "
                     "start is simulated but left out of the fit, and the model, which does "
                     "not see the stage at rest, starts other records at its loop's centre "
                     "(a record that begins at rest identifies that rest)")
    skip = burn_in(u, at_rest) if skip is None else int(skip)
    if not 0 <= skip < len(u) - 1:
        raise IdentificationDataError(f"record {record.name!r}: skip={skip} leaves no samples "
                                      f"to fit (expected 0 <= skip < {len(u) - 1})")
    weight = ~bad
    weight[:skip] = False
    du = np.abs(np.diff(u))
    slew = np.quantile(du, 0.999) if len(du) else 0.0
    if len(du) and du[-1] > JUMP_SLEWS * max(slew, 1e-300):
        weight[-1] = False
        notes.append(f"the input jumps by {du[-1]:.4g} on its last sample (a generator "
                     "wrapping round?); that sample is left out of the fit")
    for j, n in jumps:
        weight[j:j + n] = False
        notes.append(f"the input jumps by {du[j - 1]:.4g} at sample {j}, {du[j - 1] / slew:.0f} "
                     f"times the slew it otherwise holds; the {n} samples after it (until the "
                     "input has travelled half its range) are simulated but left out of the fit")
    if weight.sum() < 0.5 * len(u):
        swapped = ("; the output does not move over most of the record while the input does: "
                   "are the u and y columns swapped (--columns)?" if _still_output(u, y)
                   else "")
        raise IdentificationDataError(
            f"record {record.name!r}: only {int(weight.sum())} of {len(u)} samples are usable "
            f"({'; '.join(notes)}){swapped}")
    weight &= kept
    prep = Prepared(record, u_rest, u_scale, y_ref, y_scale, (u - u_rest) / u_scale,
                    (y - y_ref) / y_scale, weight, at_rest, skip, Envelope.of(u[:1]), notes)
    prep.envelope = Envelope.of(u[prep.fitted], from_rest=at_rest)
    prep.held = None if kept.all() else ~kept
    return prep
