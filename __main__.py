"""``python -m mirrorcap``: the MirrorCap command line."""

import sys

from .core.cli import main

sys.exit(main())
