"""``python -m ermrl``: the ``ermrl`` command."""

import sys

from ermrl.cli import main

sys.exit(main())
