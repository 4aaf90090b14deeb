"""``python -m hystid.cli``: the same as the ``hystid`` command."""

import sys

from . import main

sys.exit(main())
