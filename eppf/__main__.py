"""``python -m eppf``: the same as the ``eppf`` command."""

import sys

from .cli import main

sys.exit(main())
