"""hystid: on-line identification of piezo-driven precision positioning stages.

Data flows one way: a :class:`~hystid.records.Record` is identified into a
:class:`~hystid.model.DuhemSandwich`, whose blocks are python-control objects used for design and
diagnosis.

hystid's linear algebra works on small or tall, thin matrices (Jacobians of some 20 000 x 30),
where a multi-threaded BLAS gains nothing and, on a machine whose cores are busy, loses up to
two orders of magnitude (a 20 000 x 27 QR: 15 ms on one thread, 1.7 s on two threads competing
with other work). Imported before numpy, hystid therefore asks BLAS for one thread, unless the
user's environment already says otherwise (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``,
``MKL_NUM_THREADS``). ``hystid`` on the command line always imports it first. Imported after
numpy, its fitting entry points limit BLAS to one thread while they run
(:func:`hystid.blas.one_blas_thread`).
"""

import os as _os
import sys as _sys

if "numpy" not in _sys.modules:
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        _os.environ.setdefault(_var, "1")

from .model import DuhemSandwich, InitialCondition, Structure
from .modelfile import load_model, save_model

__all__ = ["DuhemSandwich", "InitialCondition", "SandwichResponse", "Structure", "load_model",
           "save_model"]
__version__ = "0.1.0"


def __getattr__(name: str):
    # SandwichResponse subclasses control.TimeResponseData: python-control loads on first use
    if name == "SandwichResponse":
        from .response import SandwichResponse

        return SandwichResponse
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
