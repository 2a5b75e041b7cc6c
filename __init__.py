"""MirrorCap as a Blender extension (``bl_ext.<repo>.mirrorcap``) and as the
``mirrorcap`` Python package.

Importing this package never imports ``bpy``: Blender calls :func:`register`,
which loads the Blender layer (:mod:`.addon`) only then. Outside Blender,
``mirrorcap.core`` is the numerical core and ``python -m mirrorcap`` the command line
(:mod:`.cli`). ``docs/architecture.md`` shows how the packages fit together.
"""

from .core import __version__


def register():
    from . import addon

    addon.register()


def unregister():
    from . import addon

    addon.unregister()


__all__ = ["__version__", "register", "unregister"]
