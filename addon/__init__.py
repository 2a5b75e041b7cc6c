"""MirrorCap's Blender layer: everything that touches ``bpy`` / ``mathutils``, grouped per
feature, each folder with its operators and panels: :mod:`.capture`, :mod:`.track`,
:mod:`.head`, :mod:`.bake`; what they share is in :mod:`.common` (the operator base classes,
the one core <-> Blender axis conversion, settings, head objects, takes as empties).

Registration runs in documented stages; :func:`register` runs them in order and
:func:`unregister` in reverse:

1. properties -- the scene's settings group and the add-on preferences
   (:mod:`.common.properties`), then ``Scene.mirrorcap``;
2. operators  -- every ``mirrorcap.*`` operator, feature by feature;
3. panels     -- the "MirrorCap" sidebar tabs of the Movie Clip Editor (capture, track) and
   the 3D View (take, head, bake).

The numbers all come from ``..core``; this layer reads and writes Blender data.
"""

import bpy

from ..core import __version__
from . import bake, capture, head, retarget, track
from .common import properties

FEATURES = (capture, track, head, bake, retarget)
PROPERTY_CLASSES: tuple = properties.CLASSES
OPERATOR_CLASSES: tuple = tuple(cls for feature in FEATURES for cls in feature.OPERATORS)
PANEL_CLASSES: tuple = tuple(cls for feature in FEATURES for cls in feature.PANELS)

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
