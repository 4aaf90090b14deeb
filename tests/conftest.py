"""Test-session set-up: one BLAS thread, as ``import hystid`` asks when it comes first.

The test modules import numpy before hystid, so hystid's own request would come too late;
here it comes before either (see ``hystid/__init__.py`` for why one thread).
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
