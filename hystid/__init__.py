"""hystid: on-line identification of piezo-driven precision positioning stages.

Data flows one way: a :class:`~hystid.records.Record` is identified into a
:class:`~hystid.model.DuhemSandwich`, whose blocks are python-control objects used for design and
diagnosis.
"""

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
