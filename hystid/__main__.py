"""``python -m hystid``: the same as the ``hystid`` command."""

import sys

from .cli import main

sys.exit(main())
