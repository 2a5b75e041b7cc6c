"""The ``mirrorcap`` command line: one parser (:mod:`.parser`), the commands
(:mod:`.commands`; ``bpy`` is imported only by the ones that need Blender) and the batch
worker pool (:mod:`.batch`)."""

from .parser import entry, main

__all__ = ["entry", "main"]
