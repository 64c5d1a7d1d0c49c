"""A vertex target: the AO as a color attribute per vertex of the object's mesh (its thickness
and bent normals as attributes too), wired into its materials when asked (targets.Target)."""

import numpy as np

from ..core import metrics
from ..core.native import CanopyAOError
from . import bent_io, cycles_check, gltf_io, maps_io, materials, mesh_io
from .targets import Target, check_wiring, wire_undo


class VertexTarget(Target):
    """A color attribute per vertex."""

    kind = "vertex"
    kinds = "vertices"
    on_mesh = True
    per_vertex = True

    def __init__(self, item, obj, opts, depsgraph=None):
        super().__init__(item, obj, item.positions, item.normals)
        if not self.count:
            raise CanopyAOError(f"Object '{obj.name}': its mesh has no vertices, so nothing "
                                "can be baked into it; give it geometry, set its role to "
                                "Ignore, or leave it out of the bake (nothing was changed)")
        if opts["channel"] != "RGBA":  # one channel: any color attribute, when asked
            why = maps_io.check_channel_attribute(obj, opts["attribute"])
        else:
            why = mesh_io.check_attribute(obj, opts["attribute"], opts["overwrite"])
        if not why and opts["thickness"]:
            why = mesh_io.check_attribute(obj, opts["thickness_name"], opts["overwrite"])
        if not why and opts["bent_normals"] != "OFF":
            why = mesh_io.check_attribute(obj, opts["bent_normals_name"], opts["overwrite"])
        if why:
            raise mesh_io.MeshIOError(why + " (nothing was changed)")
        check_wiring(obj, opts)
        if opts["bent_normals"] == "TANGENT":
            self.frames = bent_io.vertex_frames(obj, depsgraph, opts["uv_map"] or None,
                                                self.count)

    @classmethod
    def of_frame(cls, item, obj):
        """A target of a live frame's item: its vertices as the item has them now, nothing
        checked again (the bake that started the session checked them)."""
        t = cls.__new__(cls)
        Target.__init__(t, item, obj, item.positions, item.normals)
        return t

    def cut(self, a, b, size):
        """A vertex's rays follow its id, so any split gives the same AO."""
        return [(c, min(c + size, b)) for c in range(a, max(b, a + 1), size)]

    def vertices(self, a, b):
        return slice(a, b)

    def shared_ao(self, means):
        return means.get(self.item.name)

    @classmethod
    def attribute(cls, opts):
        return opts["attribute"]

    @classmethod
    def write_all(cls, targets, txn, opts, last=False, checked=False):
        """last: the last target's AO attribute is written last of all (see write()).
        checked is False for a modal bake: it yielded to the UI, and the user may have painted
        since."""
        for i, t in enumerate(targets):
            t.write(txn, opts, last=last and i == len(targets) - 1, checked=checked)
        return {}

    def write(self, txn, opts, last=False, checked=False):
        """last: nothing that can fail follows this write in the commit; the AO attribute is
        then written last here too, and its old values need no copy (commit.Transaction).
        checked: nothing ran between the check made when this target was read and this write
        (a blocking bake), so the AO attribute is not read back and fingerprinted again."""
        if self.thickness is not None:
            txn.attribute(self.obj, opts["thickness_name"])
            mesh_io.write_ao_attribute(self.obj, opts["thickness_name"], self.thickness,
                                       overwrite=opts["overwrite"])
        if self.bent is not None:
            txn.attribute(self.obj, opts["bent_normals_name"])
            bent_io.write_attribute(self.obj, opts["bent_normals_name"], self.bent,
                                    overwrite=opts["overwrite"])
        if opts["wire_material"]:  # the nodes name the attributes: they need not exist yet
            wire_undo(txn, self.obj)
            if opts["channel"] == "RGBA":  # a packed channel is for engines, not multiplied
                materials.wire_vertex_ao(self.obj, opts["attribute"], opts["aov_name"])
            if self.thickness is not None:
                maps_io.wire_thickness(self.obj, "vertex", opts["thickness_name"],
                                       opts["thickness_name"])
        if opts["channel"] != "RGBA":
            txn.attribute(self.obj, opts["attribute"])
            maps_io.write_attribute_channel(self.obj, opts["attribute"], self.ao,
                                            opts["channel"])
        else:
            txn.attribute(self.obj, opts["attribute"], last=last)
            mesh_io.write_ao_attribute(self.obj, opts["attribute"], self.ao,
                                       overwrite=opts["overwrite"], checked=checked)
        if opts["gltf"]:  # the attribute exists now: make it the one exported as COLOR_0
            gltf_io.set_color_export(self.obj, opts["attribute"], txn)


    @classmethod
    def check_cycles(cls, context, targets, distance, samples, rep):
        """One Cycles bake for every vertex target, compared vertex by vertex."""
        ref = cycles_check.bake_cycles_vertex_ao(context, [t.obj for t in targets], distance,
                                                 samples)
        for t in targets:
            name = t.item.name
            if name in ref and np.shape(ref[name]) != t.ao.shape:
                rep["notes"].append(f"{name}: Cycles check skipped (its modifiers change "
                                    "the vertex count)")
            elif name in ref:
                used = mesh_io.cornered_vertices(t.obj.data)
                rep["objects"][name]["cycles"] = {
                    k: float(v) for k, v in metrics.compare(t.ao, ref[name], mask=used).items()}
