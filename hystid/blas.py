"""One BLAS thread while hystid fits: its linear algebra is small or tall and thin.

hystid's fits solve Jacobians of some 20 000 x 30; a multi-threaded BLAS gains nothing there
and, on a machine whose cores are busy, loses up to two orders of magnitude (measured on stage A's
`prbn_1`, a Duhem fit after ``import control``: 12.6 s and 5.0 s with two BLAS threads on a loaded
2-core machine, 2.3 s with one). Imported before numpy, :mod:`hystid` sets the environment so
that BLAS starts with one thread. Imported after it (``import numpy`` or ``import control``
first, as most scripts do), the BLAS already runs its threads: the fitting entry points
(:func:`hystid.identify.identify`, :func:`hystid.diagnose.diagnose`...) then limit it to one
thread for their own duration with `threadpoolctl <https://github.com/joblib/threadpoolctl>`_,
and give the user's setting back when they return. A thread count the user's environment sets
(``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``) is left as it is.
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["THREAD_VARIABLES", "one_blas_thread"]

#: Environment variables through which a user sets BLAS's thread count.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

F = TypeVar("F", bound=Callable[..., Any])
_inside = threading.local()


def one_blas_thread(func: F) -> F:
    """Run ``func`` with BLAS limited to one thread, unless the environment sets the count.

    Nested calls (an entry point calling another) limit once, at the outermost call.

    Parameters
    ----------
    func : callable
        A function whose work is hystid's own linear algebra.

    Returns
    -------
    callable
        ``func`` wrapped (same name, docstring and signature).
    """

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if getattr(_inside, "active", False) or any(v in os.environ for v in THREAD_VARIABLES):
            return func(*args, **kwargs)
        from threadpoolctl import threadpool_limits

        _inside.active = True
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                return func(*args, **kwargs)
        finally:
            _inside.active = False

    return wrapper  # type: ignore[return-value]
