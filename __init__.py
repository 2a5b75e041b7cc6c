"""MirrorCap as a Blender extension (``bl_ext.<repo>.mirrorcap``) and as the
``mirrorcap`` Python package.

Importing this package never imports ``bpy``: Blender calls :func:`register`,
which loads the Blender layer (:mod:`.addon`) only then. Outside Blender,
``mirrorcap.core`` is the numerical core and ``python -m mirrorcap`` the command line
(:mod:`.cli`). ``docs/architecture.md`` shows how the packages fit together.
"""

# Blender imports this file as the package bl_ext.<repo>.mirrorcap, Python as mirrorcap; pytest imports it alone,
# as "__init__", when the repository's folder is no Python name (a clone in "mirrorcap-main" or "my clone")
if __package__:
    from .core import __version__


def register():
    from . import addon

    addon.register()


def unregister():
    from . import addon

    addon.unregister()


__all__ = ["__version__", "register", "unregister"]
