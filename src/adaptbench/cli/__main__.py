"""`python -m adaptbench.cli` runs `adapt`."""

import sys

from .main import main

sys.exit(main())
