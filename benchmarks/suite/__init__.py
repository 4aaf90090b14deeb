"""hystid's asv suite: ``time_*`` / ``peakmem_*`` in :mod:`.speed`, ``track_*`` in
:mod:`.accuracy`. The workloads and figures themselves live in ``benchmarks/workloads.py`` and
``benchmarks/figures.py`` (shared with the gate and the scripts), imported from the folder
above this one."""

import sys
from pathlib import Path

_BENCHMARKS = str(Path(__file__).resolve().parents[1])
if _BENCHMARKS not in sys.path:
    sys.path.insert(0, _BENCHMARKS)
