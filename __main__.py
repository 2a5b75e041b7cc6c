"""``python -m mirrorcap``: the MirrorCap command line."""

import sys

from .cli import main

sys.exit(main())
