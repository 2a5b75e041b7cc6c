"""MirrorCap as a Blender extension (``bl_ext.<repo>.mirrorcap``) and as the
``mirrorcap`` Python package.

Importing this package never imports ``bpy``: Blender calls :func:`register`,
which loads the Blender layer (``mirrorcap_addon``) only then. Outside Blender,
``mirrorcap.core`` is the numerical core and ``python -m mirrorcap`` the CLI.
"""

from .core import __version__


def register():
    from . import mirrorcap_addon

    mirrorcap_addon.register()


def unregister():
    from . import mirrorcap_addon

    mirrorcap_addon.unregister()


__all__ = ["__version__", "register", "unregister"]
