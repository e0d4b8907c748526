"""``python -m probreg`` runs the command line (as the ``probreg`` script does)."""

import sys

from .cli import main

sys.exit(main())
