"""Filigree for Blender: upload a detailed mesh to a Filigree server, edit,
sculpt or pose the small base mesh it gives back, and watch the detailed
mesh follow live — alone, or in a session shared with others.

Needs the `filigree` Python package (client/python; bundled in the add-on zip
as `vendor/`, or installed with `make install`) and libfiligree.so (set its
path in the add-on's preferences unless `make install` put it in
/usr/local/lib). Blender 3.4 (Debian 12) to 4.x."""

bl_info = {
    "name": "Filigree live deformation",
    "author": "Filigree",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > Filigree",
    "description": "Detail-preserving deformation of a mesh from edits of its base mesh, live and shared",
    "category": "Mesh",
}

from . import operators, panel, properties  # noqa: E402  (after bl_info, as Blender reads it)

_modules = (properties, operators, panel)


def register() -> None:
    for module in _modules:
        module.register()


def unregister() -> None:
    for module in reversed(_modules):
        module.unregister()
