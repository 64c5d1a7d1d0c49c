"""Instanced trees in Blender: find them, bake each prototype once, let every instance occlude
(docs/DESIGN.md, 'How each role is lit'; the math is in core/forest.py, which needs no
bpy).

Instances come from the evaluated depsgraph (``depsgraph.object_instances``), which covers
particle systems, collection-instance empties and geometry-nodes instances alike. Each instance
of mesh object O gives the matrix M = instance.matrix_world · O.matrix_world⁻¹, which maps O as
it stands in the scene (the prototype's space) onto the instance. Prototype objects are grouped
into trees as the bake groups real objects (gather.tree_of: usually the collection that is
instanced), each tree is fitted and baked once with the engine (its self-AO, written to the
prototype's mesh, which the instances share), and its shells and trunks, moved by every M, are
occluders for everything the main bake evaluates; the exact rung and auto's calibration trace
its triangles at every M (Embree instances).

Limits: geometry instanced without an object (a geometry-nodes primitive realised inside the
node tree) has no prototype object and is skipped; a prototype's self-AO does not include the
ground or neighbouring instances (the mesh is shared, so one value per vertex must do for every
instance).
"""

import numpy as np

from . import gather, materials, mesh_io
from .. import core
from ..core import forest


def instance_matrices(depsgraph):
    """{original object name: (object, matrices float64 (N, 4, 4))} for every mesh instance,
    M mapping the object as it stands in the scene onto the instance."""
    found = {}
    for inst in depsgraph.object_instances:
        if not inst.is_instance:
            continue
        ob = inst.instance_object
        if ob is None or ob.type != 'MESH':
            continue
        orig = ob.original
        parent = inst.parent.original if inst.parent is not None else None
        if orig is None or orig == parent or orig.get(mesh_io.PROXY_PROP):
            continue  # no prototype object of its own (geometry made by the node tree)
        found.setdefault(orig.name, (orig, []))[1].append(
            np.array(inst.matrix_world, dtype=np.float64))
    out = {}
    for name, (orig, mats) in found.items():
        inv = np.linalg.pinv(np.array(orig.matrix_world, dtype=np.float64))
        out[name] = (orig, np.stack(mats) @ inv)
    return out


class Prototypes:
    """The instanced trees of a scene: gathered (nothing changed), prepared and baked with the
    main bake's settings, written at commit."""

    def __init__(self, depsgraph, vertex_mode=True):
        self.items = {}  # tree -> [SceneItem] in the prototype's space
        self.matrices = {}  # tree -> [(N, 4, 4)] one array per object of the tree
        self.objects = {}  # item name -> original object
        self.writable = set()  # item names whose vertex count allows a per-vertex result
        self.how = {}
        self.results = []
        self.plans = {}
        for name, (obj, mats) in instance_matrices(depsgraph).items():
            try:
                pos, nor, tris = mesh_io.evaluated_arrays(obj, depsgraph, same_count=True)
                if vertex_mode:
                    self.writable.add(name)
            except mesh_io.MeshIOError:
                pos, nor, tris = mesh_io.evaluated_arrays(obj, depsgraph, same_count=False)
            role, how = gather.role_of(obj, pos, tris)
            if role == "IGNORE":
                continue
            tree = gather.tree_of(obj)
            self.items.setdefault(tree, []).append(
                core.SceneItem(name, role, tree, pos, nor, tris))
            self.matrices.setdefault(tree, []).append(mats)
            self.objects[name] = obj
            self.how[name] = how
        # Only trees with leaves are fitted (instanced rocks have no shells to occlude with).
        leafless = [t for t, its in self.items.items() if not any(i.role == "CANOPY" for i in its)]
        for tree in leafless:
            for it in self.items.pop(tree):
                self.objects.pop(it.name)
                self.writable.discard(it.name)
            self.matrices.pop(tree)

    def __bool__(self):
        return bool(self.items)

    @property
    def count(self) -> int:
        return sum(len(forest.unique_matrices(np.concatenate(m))) for m in self.matrices.values())

    def check(self, attribute, overwrite, skip=()):
        """None, or why a prototype's attribute may not be written (nothing changed)."""
        for name in sorted(self.writable - set(skip)):
            why = mesh_io.check_attribute(self.objects[name], attribute, overwrite)
            if why:
                return why
        return None

    def bake(self, settings, skip=()):
        """Fit and bake each tree once; returns forest.Prototype list (shells and mesh) for
        core.prepare, whose ray tracer and calibration then see every instance.
        Items named in ``skip`` (also baked by the main bake) are fitted but not evaluated."""
        protos = []
        for tree, items in self.items.items():
            plan = core.prepare(items, settings)
            self.plans[tree] = plan
            mats = forest.unique_matrices(np.concatenate(self.matrices[tree]))
            protos.append(forest.prototype_from_plan(plan, tree, mats, items=items))
            for it in items:
                if it.name in self.writable and it.name not in skip:
                    self.results.append(core.evaluate_item(plan, it))
        return protos

    def commit(self, txn, opts):
        """Write each prototype's attribute (and wiring), recorded in txn (commit.Transaction)."""
        from .targets import wire_undo
        for r in self.results:
            obj = self.objects[r.name]
            txn.attribute(obj, opts["attribute"])
            mesh_io.write_ao_attribute(obj, opts["attribute"], r.ao, overwrite=opts["overwrite"])
            if opts["wire_material"]:
                wire_undo(txn, obj)
                materials.wire_vertex_ao(obj, opts["attribute"], opts["aov_name"])

    def lines(self):
        out = []
        for tree, items in self.items.items():
            n = len(forest.unique_matrices(np.concatenate(self.matrices[tree])))
            plan = self.plans.get(tree)
            out.append(f"instanced tree {tree}: {n} instance(s) of "
                       f"{', '.join(i.name for i in items)}"
                       + (f", {plan.method}, τ {plan.tau:.3g}" if plan else ""))
        return out
