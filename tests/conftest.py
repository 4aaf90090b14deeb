"""Test-session set-up: one BLAS thread, as ``import hystid`` asks when it comes first.

The test modules import numpy before hystid, so hystid's own request would come too late;
here it comes before either (see ``hystid/__init__.py`` for why one thread). Also the helpers
test modules share (``from conftest import quiet``).
"""

import os
import warnings

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def quiet(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` with its warnings silenced (the tests assert on figures, and on
    warnings where they are the point)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kwargs)
