"""Export of a saved model to code that runs outside Python (``hystid export``).

:func:`export_c` writes C99 ``hystid_model.h`` / ``hystid_model.c`` with the placed model's
step, the feed-forward compensator's step and the on-line identifier's step (see
:mod:`hystid.export.c`).
"""

from __future__ import annotations

from .c import C_FILES, c_sources, export_c, ff_options, ff_plan, rpem_start
from .rpem import rpem_reference

__all__ = ["C_FILES", "c_sources", "export_c", "ff_options", "ff_plan", "rpem_reference",
           "rpem_start"]
