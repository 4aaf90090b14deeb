"""hystid: on-line identification of piezo-driven precision positioning stages.

Data flows one way: a :class:`~hystid.records.Record` is identified into a
:class:`~hystid.model.DuhemSandwich`, whose blocks are python-control objects used for design and
diagnosis.
"""

from .model import DuhemSandwich, InitialCondition, SandwichResponse, Structure

__all__ = ["DuhemSandwich", "InitialCondition", "SandwichResponse", "Structure"]
__version__ = "0.1.0"
