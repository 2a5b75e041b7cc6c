"""The base of every MirrorCap sidebar panel."""


class SidebarPanel:
    """Mixed into each panel: the sidebar (``UI`` region), tab "MirrorCap"."""

    bl_region_type = "UI"
    bl_category = "MirrorCap"
