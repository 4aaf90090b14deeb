"""A generic baseline: SysIdentPy's polynomial NARX, fitted on one record, run free on others.

The physical models are compared with it in the accuracy tables, so that a table shows whether
the sandwich beats a generic black box and not only a static line and a linear model.
SysIdentPy is in the ``bench`` extra only (``pip install -e ".[bench]"``); without it
:func:`available` is False and the tables leave the column out.

The settings are those of the comparison the issue reports: FROLS (forward regression with
orthogonal least squares), a polynomial basis of degree 3, 4 lags of the input and of the
output, 40 terms, least squares, simulated free-run from the record's own first samples, on the
record's own units: on stage A (V, um) that did better than the input and output shifted to
their first sample and scaled (43-61 nm against 43-147 nm on the held-out records), so the
baseline is given its better form.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from hystid.records import Record

#: Degree, lags and terms of the NARX (the issue's comparison).
DEGREE, LAGS, TERMS = 3, 4, 40


def available() -> bool:
    """Whether SysIdentPy is installed (the ``bench`` extra)."""
    try:
        import sysidentpy  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass
class NARX:
    """A fitted polynomial NARX.

    Attributes
    ----------
    model : object
        The fitted ``sysidentpy`` FROLS model.
    """

    model: object

    @classmethod
    def fit(cls, train: Record, degree: int = DEGREE, lags: int = LAGS,
            terms: int = TERMS) -> NARX:
        """Fit on a record.

        Parameters
        ----------
        train : Record
            The identification record.
        degree, lags, terms : int
            Polynomial degree, input and output lags, number of terms.

        Returns
        -------
        NARX
        """
        from sysidentpy.basis_function import Polynomial
        from sysidentpy.model_structure_selection import FROLS
        from sysidentpy.parameter_estimation import LeastSquares

        model = FROLS(order_selection=False, n_terms=terms, ylag=lags, xlag=lags,
                      basis_function=Polynomial(degree=degree), estimator=LeastSquares(),
                      model_type="NARMAX")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model.fit(X=train.u[:, None], y=train.y[:, None])
        return cls(model)

    def predict(self, rec: Record) -> np.ndarray:
        """Free-run prediction of a record's output from its first ``LAGS`` samples.

        Parameters
        ----------
        rec : Record
            A record of the same stage.

        Returns
        -------
        ndarray
            The predicted output in the record's units (non-finite where the run diverged).
        """
        lags = self.model.max_lag
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            yhat = self.model.predict(X=rec.u[:, None], y=rec.y[:lags, None]).ravel()
        return yhat[: rec.n]
