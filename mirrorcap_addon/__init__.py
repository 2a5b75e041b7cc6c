"""MirrorCap's Blender layer: everything that touches ``bpy`` / ``mathutils``.

Registration runs in documented stages (after Rigify):

1. properties (the add-on's property group and preferences),
2. operators,
3. panels.

Each stage lists its classes; :func:`register` registers them in that order and
:func:`unregister` removes them in reverse. Operators so far: ``mirrorcap.bake``
(:mod:`.operators`); panels arrive with the UI issue. The numbers all come from ``..core``.
"""

import bpy

from ..core import __version__
from . import operators

PROPERTY_CLASSES: tuple = ()
OPERATOR_CLASSES: tuple = operators.CLASSES
PANEL_CLASSES: tuple = ()

STAGES = (("properties", PROPERTY_CLASSES), ("operators", OPERATOR_CLASSES), ("panels", PANEL_CLASSES))


def registered_classes():
    return [cls for _, classes in STAGES for cls in classes]


def register():
    for cls in registered_classes():
        bpy.utils.register_class(cls)
    bpy.app.driver_namespace["mirrorcap_version"] = __version__


def unregister():
    for cls in reversed(registered_classes()):
        bpy.utils.unregister_class(cls)
    bpy.app.driver_namespace.pop("mirrorcap_version", None)
