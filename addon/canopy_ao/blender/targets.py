"""What a bake writes, one Target per object: its receivers (vertices, or the texels the native
rasteriser finds in its UV layout), the AO evaluated for them, and how that AO is written
(docs/DESIGN.md, 'Data flow'). Reading happens when a target is made, writing only in write()."""

import numpy as np

from . import materials, mesh_io, texel_io


class Target:
    kind = ""

    def __init__(self, item, obj, positions, normals):
        self.item, self.obj = item, obj
        self.positions, self.normals = positions, normals
        self.triangles = None  # texels: each one's triangle in the item's mesh (own rays)
        self.ao = np.ones(len(positions), np.float32)
        self.seconds = 0.0
        self.stats = {}

    @property
    def count(self):
        return len(self.positions)

    def write(self, txn, opts):
        raise NotImplementedError


def wire_undo(txn, obj):
    """Before wiring obj's materials: when none has our nodes yet, undoing unwires them."""
    mats = [s.material for s in obj.material_slots if s.material is not None]
    if not any(n.get(materials.TAG) for m in mats if m.node_tree for n in m.node_tree.nodes):
        txn.add(lambda: materials.unwire(obj))


class VertexTarget(Target):
    """A color attribute per vertex."""

    kind = "vertex"

    def __init__(self, item, obj, opts):
        super().__init__(item, obj, item.positions, item.normals)
        why = mesh_io.check_attribute(obj, opts["attribute"], opts["overwrite"])
        if why:
            raise mesh_io.MeshIOError(why + " (nothing was changed)")

    def write(self, txn, opts):
        txn.attribute(self.obj, opts["attribute"])
        mesh_io.write_ao_attribute(self.obj, opts["attribute"], self.ao,
                                   overwrite=opts["overwrite"])
        if opts["wire_material"]:
            wire_undo(txn, self.obj)
            materials.wire_vertex_ao(self.obj, opts["attribute"], opts["aov_name"])


class TexelTarget(Target):
    """An image in the UV layout: an EXR file and a Blender image, wired when asked."""

    kind = "texel"

    def __init__(self, item, obj, opts, depsgraph):
        self.rx = texel_io.receivers(obj, depsgraph, opts["uv_map"] or None,
                                     opts["resolution"])
        super().__init__(item, obj, self.rx.positions, self.rx.normals)
        # The raster's loop triangles are the item's own when the counts agree (the same
        # evaluated mesh): then a texel's rays skip only its own triangle, as Cycles' do.
        tris = self.rx.triangles
        if tris is not None and self.rx.stats.get("triangles") == len(item.triangles):
            self.triangles = tris

    def write(self, txn, opts):
        image, self.stats = texel_io.write_texels(self.obj, self.rx, self.ao,
                                                  opts["image_dir"] or None, txn)
        if opts["wire_material"]:
            wire_undo(txn, self.obj)
            self.stats["nodes_added"] = materials.wire_texel_ao(self.obj, image, self.rx.uv_map,
                                                                opts["aov_name"])

    def report(self):
        """The texel stats as plain data for the JSON report."""
        return {k: v for k, v in self.stats.items() if isinstance(v, (int, float, str, list))}
