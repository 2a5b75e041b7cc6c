"""MirrorCap's Blender layer: everything that touches ``bpy`` / ``mathutils``.

Registration runs in documented stages (after Rigify); :func:`register` runs them in order
and :func:`unregister` in reverse:

1. properties -- the scene's settings group and the add-on preferences (:mod:`.properties`),
   then ``Scene.mirrorcap``;
2. operators  -- every ``mirrorcap.*`` operator (:mod:`.operators`, jobs in :mod:`.jobs`);
3. panels     -- the "MirrorCap" sidebar tabs of the Movie Clip Editor and 3D View (:mod:`.panels`).

The numbers all come from ``..core``; this layer reads and writes Blender data.
"""

import bpy

from ..core import __version__
from . import operators, panels, properties

PROPERTY_CLASSES: tuple = properties.CLASSES
OPERATOR_CLASSES: tuple = operators.CLASSES
PANEL_CLASSES: tuple = panels.CLASSES

STAGES = (("properties", PROPERTY_CLASSES), ("operators", OPERATOR_CLASSES), ("panels", PANEL_CLASSES))


def registered_classes():
    return [cls for _, classes in STAGES for cls in classes]


def register():
    for cls in PROPERTY_CLASSES:
        bpy.utils.register_class(cls)
    properties.register_properties()
    for cls in OPERATOR_CLASSES + PANEL_CLASSES:
        bpy.utils.register_class(cls)
    bpy.app.driver_namespace["mirrorcap_version"] = __version__


def unregister():
    for cls in reversed(OPERATOR_CLASSES + PANEL_CLASSES):
        bpy.utils.unregister_class(cls)
    properties.unregister_properties()
    for cls in reversed(PROPERTY_CLASSES):
        bpy.utils.unregister_class(cls)
    bpy.app.driver_namespace.pop("mirrorcap_version", None)
