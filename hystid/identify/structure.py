"""``structure="auto"``: orders and delays chosen on held-out error.

The paper's experimental structure (first-order L1 with one sample of delay, second-order L2)
is the default at any rate. A stage sampled at another rate, or with a second mode, a longer
delay or a loop that needs the ``f0 sgn`` term, may want another one: :func:`select_structure`
fits each candidate on the head of the record and scores it on the tail (simulated on from the
head, so the tail's state is the model's own), and keeps the best unless a simpler candidate
is within :data:`PARSIMONY` of it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..blas import one_blas_thread
from ..model import Structure
from ..records import Record

__all__ = ["CANDIDATES", "PARSIMONY", "select_structure"]

#: A candidate with more parameters must lower the held-out RMS by this share to be kept.
PARSIMONY = 0.02


def _candidates() -> dict[str, Structure]:
    paper = Structure()
    return {
        "paper": paper,
        "q1=2": replace(paper, q1=2),
        "q1=3": replace(paper, q1=3),
        "n2a=4 (two modes)": replace(paper, n2a=4),
        "n2b=1": replace(paper, n2b=1),
        "f0": replace(paper, f0=True),
    }


#: The candidate structures, by label.
CANDIDATES = _candidates()


@one_blas_thread
def select_structure(
    record: Record, candidates: dict[str, Structure] | None = None, holdout: float = 0.25,
    max_nfev: int = 80,
) -> tuple[Structure, list[dict]]:
    """Choose the structure on the held-out tail of a record.

    Parameters
    ----------
    record : Record
        Identification record.
    candidates : dict of str to Structure, optional
        :data:`CANDIDATES` by default.
    holdout : float
        Share of the record's excitation held out at its end
        (:func:`~hystid.identify.prepare.held_out_from`).
    max_nfev : int
        Evaluations of each candidate's polish.

    Returns
    -------
    structure : Structure
        The chosen structure.
    table : list of dict
        Per candidate: ``label``, ``parameters``, ``heldout_rms`` (record units; ``None`` when
        the fit failed) and ``error``.
    """
    from .offline import fit_output_error

    candidates = candidates or CANDIDATES
    from .prepare import held_out_from

    split = held_out_from(record.u, holdout)
    head = record[:split]
    table = []
    for label, structure in candidates.items():
        row = {"label": label, "parameters": len(structure.names) + 1, "heldout_rms": None,
               "error": None}
        try:
            model = fit_output_error(head, structure, max_nfev=max_nfev).model
            with np.errstate(over="ignore", invalid="ignore"):
                yhat = model.simulate(record.u, check=False).y
            rms = float(np.sqrt(np.mean((yhat[split:] - record.y[split:]) ** 2)))
            row["heldout_rms"] = rms if np.isfinite(rms) else None
        except ValueError as err:
            row["error"] = str(err)
        table.append(row)
    scored = [r for r in table if r["heldout_rms"] is not None]
    if not scored:
        return Structure(), table
    best = min(scored, key=lambda r: r["heldout_rms"])
    simple = [r for r in scored if r["parameters"] < best["parameters"]
              and r["heldout_rms"] <= (1.0 + PARSIMONY) * best["heldout_rms"]]
    chosen = min(simple, key=lambda r: (r["parameters"], r["heldout_rms"])) if simple else best
    for r in table:
        r["chosen"] = r is chosen
    return candidates[chosen["label"]], table
