"""A bake's refusals that need no geometry, made before any work (BakeJob, before it reads a
mesh): the native module, live, the AOV's, thickness's and bent normals' names. What needs the
geometry is refused where it is read (mesh_io.evaluated_arrays: non-finite positions;
vertex_target.py: an object with nothing to bake), still before the first write."""

from .. import core
from ..core.native import CanopyAOError
from . import bent_io, live_session, materials


def check_request(opts):
    """Raise CanopyAOError when the bake opts asks for cannot be done."""
    ok, msg = core.core_status()
    if not ok:
        raise CanopyAOError(msg)
    if opts["live"]:
        live_session.check_request(opts)  # texels or a non-live rung: refused before any work
    if opts["wire_material"] or opts["add_aov"]:
        try:
            materials.check_aov_name(opts["aov_name"])
            if opts["thickness"] and opts["wire_material"]:
                materials.check_aov_name(opts["thickness_name"])
        except ValueError as exc:
            raise CanopyAOError(str(exc)) from None
    if opts["thickness"] and opts["thickness_name"] in ("", opts["attribute"],
                                                        opts["aov_name"]):
        raise CanopyAOError(f"the thickness's name '{opts['thickness_name']}' is empty or "
                            "also the AO's attribute or AOV; give it a name of its own")
    if opts["bent_normals"] != "OFF":
        bent_io.check_request(opts)
