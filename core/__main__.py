"""``python -m core`` from a source checkout: the ``mirrorcap`` command line."""

import sys

from .cli import main

sys.exit(main())
