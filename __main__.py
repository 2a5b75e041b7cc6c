"""``python -m mirrorcap``: the MirrorCap command line."""

import sys

from .cli import entry

sys.exit(entry())
