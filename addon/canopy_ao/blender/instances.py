"""Instanced trees in Blender: find them, bake each prototype once, let every instance occlude
(docs/DESIGN.md, 'How each role is lit'; the math is in core/forest.py, which needs no
bpy).

Instances come from the evaluated depsgraph (``depsgraph.object_instances``), which covers
particle systems, collection-instance empties and geometry-nodes instances alike. Each instance
of mesh object O gives the matrix M = instance.matrix_world · O.matrix_world⁻¹, which maps O as
it stands in the scene (the prototype's space) onto the instance. Prototype objects are grouped
into trees as the bake groups real objects (gather.tree_of: usually the collection that is
instanced), each tree is fitted once with the engine, and its shells and trunks, moved by every
M, are occluders for everything the main bake evaluates; the exact rung and auto's calibration
trace its triangles at every M (Embree instances). A prototype's self-AO (written to its mesh,
which the instances share) is baked only when asked for: the prototype or an object that
instances it is a target, or the bake is of everything; a bake of the ground alone leaves the
trees' meshes untouched.

A geometry-nodes instance of an object (Object Info, a collection on points) names the
instancer as its object; its prototype is found by the instanced mesh (_mesh_owner).
Limits: geometry instanced without an object (a geometry-nodes primitive made inside the
node tree) has no prototype object and is skipped; a prototype's self-AO does not include the
ground or neighbouring instances (the mesh is shared, so one value per vertex must do for every
instance).
"""

import time

import bpy
import numpy as np

from . import gather, materials, mesh_io, opacity_io, ownership
from .visibility import RenderVisibility
from .. import core
from ..core import forest, forest_fit, opacity, roles

# A blade's AO per vertex is its mean over this many of its instances at most (evenly spread
# over the field): the mean of 2000 is within ~0.005 of all of them, at a bounded cost.
MEAN_INSTANCES = 2000


def _mesh_owner(instance_object, owners, depsgraph):
    """The mesh object whose mesh a geometry-nodes instance shows (an Object Info or a
    collection's object instanced on points: Blender names the instancer as the instance's
    object, and its data a copy of the instanced object's evaluated mesh, under that mesh's
    name), or None when no mesh object of that name and size is found (a mesh the node tree
    made). owners: a dict kept over one pass, (mesh name, vertices) -> object."""
    data = instance_object.data
    if not isinstance(data, bpy.types.Mesh):
        return None
    key = (data.name, len(data.vertices))
    if key not in owners:
        owners[key] = next((o for o in bpy.data.objects
                            if o.type == 'MESH' and o.data.name == data.name
                            and o.data.library is None
                            and len(o.evaluated_get(depsgraph).data.vertices)
                            == key[1]), None) if data.name in bpy.data.meshes else None
    return owners[key]


def instance_matrices(depsgraph):
    """{original object name: (object, matrices float64 (N, 4, 4), instancer names)} for every
    mesh instance, M mapping the object as it stands in the scene onto the instance; the
    instancers are the objects whose particles or node tree made the instances (None: none).
    Only instances that occlude in Cycles (visibility.py: the instancer renders, both cast
    shadows, a collection instance's own render flags)."""
    found, owners = {}, {}
    vis = RenderVisibility(depsgraph.view_layer)
    for inst in depsgraph.object_instances:
        if not inst.is_instance:
            continue
        ob = inst.instance_object
        if ob is None or (ob.type != 'MESH' and ob.type not in gather.SOLID_TYPES):
            continue
        orig = ob.original
        parent = inst.parent.original if inst.parent is not None else None
        if orig is not None and orig == parent:  # geometry nodes: the mesh's own object
            orig = _mesh_owner(inst.object, owners, depsgraph)
        if orig is None or orig == parent or orig.get(mesh_io.PROXY_PROP):
            continue  # no prototype object of its own (geometry made by the node tree)
        if not vis.instance_renders(orig, parent):
            continue
        entry = found.setdefault(orig.name, (orig, [], set()))
        entry[1].append(np.array(inst.matrix_world, dtype=np.float64))
        entry[2].add(parent.name if parent is not None else None)
    out = {}
    for name, (orig, mats, parents) in found.items():
        inv = np.linalg.pinv(np.array(orig.matrix_world, dtype=np.float64))
        out[name] = (orig, np.stack(mats) @ inv, parents)
    return out


def _copies(items, matrices):
    """[(item, mirrored bool (k,))]: the copies forest.realize makes of each item (singular
    matrices dropped, items without copies or vertices left out), those it mirrors flagged."""
    out = []
    for it, mats in zip(items, matrices):
        det = np.linalg.det(np.asarray(mats, np.float64).reshape(-1, 4, 4)[:, :3, :3])
        det = det[np.abs(det) > 1e-12]
        if len(det) and len(it.positions):
            out.append((it, det < 0))
    return out


class Prototypes:
    """The instanced trees of a scene: gathered (nothing changed), prepared and baked with the
    main bake's settings, written at commit."""

    def __init__(self, depsgraph, vertex_mode=True, targets=None):
        """targets: the bake's target names; a prototype's own AO is baked and written only
        when it or an object that instances it is one (None: every prototype, the bake of
        everything). The others are fitted alone: they occlude, their meshes are not touched."""
        self.items = {}  # tree -> [SceneItem] in the prototype's space
        self.matrices = {}  # tree -> [(N, 4, 4)] one array per object of the tree
        self.objects = {}  # item name -> original object
        self.writable = set()  # item names asked for whose vertex count allows a result
        self.how = {}
        self.results = []
        self.plans = {}
        self.means = {}  # prototype object name -> its vertices' mean AO over the instances
        self.instancers = {}  # item name -> names of the objects that instance it
        alphas = {}  # each material's alpha, read once (gather.scene_items')
        for name, (obj, mats, parents) in instance_matrices(depsgraph).items():
            self.instancers[name] = parents
            asked = targets is None or name in targets or bool(parents & set(targets))
            try:  # a curve, text, surface or metaball occludes as its mesh, never written
                pos, nor, tris = mesh_io.evaluated_arrays(obj, depsgraph,
                                                          same_count=obj.type == 'MESH')
                if vertex_mode and asked and obj.type == 'MESH':
                    self.writable.add(name)
            except mesh_io.MeshIOError:
                pos, nor, tris = mesh_io.evaluated_arrays(obj, depsgraph, same_count=False)
            role, how = gather.role_of(obj, pos, tris)
            if role == "IGNORE":
                continue
            tree = gather.tree_of(obj)
            it = core.SceneItem(name, role, tree, pos, nor, tris)
            if len(tris):  # leaf cards: what their alpha keeps (realised, they honour it)
                it.opacity = opacity_io.item_opacity(obj, depsgraph, len(tris), alphas)
            self.items.setdefault(tree, []).append(it)
            self.matrices.setdefault(tree, []).append(mats)
            self.objects[name] = obj
            self.how[name] = how
        # Instances without leaves of their own tree: grass (a blade or a clump scattered by a
        # particle system or geometry nodes), or leaves one object scatters (a crown volume's
        # particles), is realised as one item, so that every rung sees it as it sees the same
        # made real; anything else (rocks, bare trees) stays instanced, its mesh traced at
        # every instance by the exact rung, its trunks solid occluders of the rest.
        self.realized = []  # forest.Realized: one world-space GRASS or CANOPY item each
        self.realized_objects = {}  # prototype object name -> original object
        self.mesh_only = set()  # trees too big to realise: traced by the exact rung alone
        self.notes = []
        for name in sorted(self.writable):  # another file's mesh: it occludes, unwritten
            why = ownership.linked(self.objects[name].data) if name in self.objects else None
            if why:
                self.writable.discard(name)
                self.notes.append(
                    f"instanced {name}: its mesh '{self.objects[name].data.name}' is {why}, "
                    "so its AO was not written (Blender would not save it); it still "
                    "occludes. Make it local (Object > Relations > Make Local) to bake it")
        leafless = [t for t, its in self.items.items() if not any(i.role == "CANOPY" for i in its)]
        for tree in leafless:
            grass = self._realized_field(tree)
            if grass is None:
                continue
            self.realized.append(grass)
            for it in self.items.pop(tree):
                self.realized_objects[it.name] = self.objects.pop(it.name)
            self.matrices.pop(tree)

    def _realized_field(self, tree):
        """forest.Realized of a leafless tree's instances when they are grass (declared on a
        prototype, or guessed on the realised field: a single blade alone looks like anything)
        or the leaves of the one object that scatters them, else None."""
        items, mats = self.items[tree], self.matrices[tree]
        declared = [gather.declared_role(self.objects[it.name]) for it in items]
        if any(d is not None and d[0] not in ("GRASS", "IGNORE") for d in declared):
            return None
        size = sum(len(it.positions) * len(m) for it, m in zip(items, mats))
        names = ", ".join(it.name for it in items)
        if size > forest.MAX_REALIZED_VERTICES:
            self.mesh_only.add(tree)
            self.notes.append(
                f"instances of {names}: {size:,} vertices in all, over the "
                f"{forest.MAX_REALIZED_VERTICES:,} that are realised into one field; they "
                "stay instances (the exact rung traces them, the other rungs do not see them)")
            return None
        count = max(len(m) for m in mats)
        real = forest.realize(items, mats, f"{names} (×{count} instances)", "GRASS", tree)
        if real is None:
            return None
        it = real.item
        it.opacity = opacity.tiled(_copies(items, mats))
        if any(d is not None and d[0] == "GRASS" for d in declared):
            how = "declared Grass on the prototype"
        else:
            role, why = roles.guess_role(it.positions, it.triangles)
            how = f"guessed on its {count} instances: {why}"
            if role == "CANOPY":
                # Leaves scattered by one object (a crown volume's or a trunk's particles):
                # that object's tree's canopy, realised as the same leaves made real would be.
                parents = set().union(*(self.instancers[i.name] for i in items))
                if len(parents) != 1 or None in parents:
                    return None
                (parent,) = parents
                it.role = "CANOPY"
                it.tree, it.tree_source = gather.tree_and_source(bpy.data.objects[parent])
                how += f", the leaves of {parent}'s tree"
            elif role != "GRASS":
                return None
        for i in items:
            self.how[i.name] = how
        self.how[it.name] = how
        return real

    def __bool__(self):
        return bool(self.items or self.realized)

    @property
    def count(self) -> int:
        return (sum(len(forest.unique_matrices(np.concatenate(m)))
                    for m in self.matrices.values())
                + sum(r.instances for r in self.realized))

    def _object(self, name):
        return self.objects[name] if name in self.objects else self.realized_objects[name]

    @property
    def realized_items(self):
        """The realised instances (grass fields, scattered leaves) as world-space SceneItems:
        occluders of the main bake (never its targets), lit as the same made real."""
        return [r.item for r in self.realized]

    def check(self, attribute, overwrite, skip=()):
        """None, or why a prototype's attribute may not be written (nothing changed)."""
        for name in sorted(self.writable - set(skip)):
            why = mesh_io.check_attribute(self._object(name), attribute, overwrite)
            if why:
                return why
        return None

    def bake(self, settings, skip=()):
        """Fit and bake each tree once; returns forest.Prototype list (shells and mesh) for
        core.prepare, whose ray tracer and calibration then see every instance.
        Items named in ``skip`` (also baked by the main bake) are fitted but not evaluated."""
        protos = []
        for tree, items in self.items.items():
            mats = forest.unique_matrices(np.concatenate(self.matrices[tree]))
            if tree in self.mesh_only:  # no solids: a fitted ellipsoid per blade is no trunk
                protos.append(forest.Prototype(tree, [], 1.0, mats,
                                               mesh=forest.prototype_mesh(items)))
                continue
            # Its fit is what every instance occludes with; calibrated on the prototype only
            # when its own AO is baked (here, or by the main bake: a target).
            own = any(it.name in self.writable or it.name in skip for it in items)
            plan = None if own else forest_fit.fit_only(items, settings)
            plan = plan or core.prepare(items, settings)
            self.plans[tree] = plan
            protos.append(forest.prototype_from_plan(plan, tree, mats, items=items))
            for it in items:
                if it.name in self.writable and it.name not in skip:
                    self.results.append(core.evaluate_item(plan, it))
        return protos

    def bake_realized(self, plan):
        """Bake each realised field (grass, scattered leaves) with the main bake's plan (which
        lit it as an occluder) and give every prototype vertex its mean over the instances (the
        mesh is shared: one value per vertex must do for the whole field). Returns {object name:
        float32 (V,)} for every writable prototype; those that are not targets of the main
        bake also go into self.results (written at commit)."""
        self.means = {}
        for real in self.realized:
            names = [n for n in real.objects if n in self.writable]
            if not names:
                continue
            t0 = time.perf_counter()
            for name, idx, k, v in real.sample_vertices(MEAN_INSTANCES, names):
                it = real.item
                ao = core.evaluate_receivers(plan, it, it.positions[idx], it.normals[idx],
                                             vertices=idx)
                self.means[name] = ao.reshape(k, v).mean(axis=0).astype(np.float32)
                self.results.append(core.ItemResult(name, it.role, it.tree, plan.method,
                                                    self.means[name],
                                                    time.perf_counter() - t0))
        return self.means

    def commit(self, txn, opts, skip=()):
        """Write each prototype's attribute (and wiring), recorded in txn (commit.Transaction).
        Objects named in ``skip`` are the main bake's targets, written by it."""
        from .targets import wire_undo
        for r in self.results:
            if r.name in skip:
                continue
            obj = self._object(r.name)
            txn.attribute(obj, opts["attribute"])
            mesh_io.write_ao_attribute(obj, opts["attribute"], r.ao, overwrite=opts["overwrite"])
            if opts["wire_material"]:
                wire_undo(txn, obj)
                materials.wire_vertex_ao(obj, opts["attribute"], opts["aov_name"])

    def grass_lines(self):
        """What became of instances without leaves (also the bake report's notes)."""
        out = list(self.notes)
        for real in self.realized:
            out.append(f"instanced {real.item.role.lower()} {real.item.tree}: "
                       f"{real.instances} instance(s) of {', '.join(real.objects)} baked as "
                       f"one field of {len(real.item.positions):,} vertices "
                       f"({self.how.get(real.item.name, '')})")
        return out

    def lines(self):
        """One line per instanced tree (what the operator reports)."""
        out = []
        for tree, items in self.items.items():
            n = len(forest.unique_matrices(np.concatenate(self.matrices[tree])))
            plan = self.plans.get(tree)
            out.append(f"instanced tree {tree}: {n} instance(s) of "
                       f"{', '.join(i.name for i in items)}"
                       + (f", {plan.method}, τ {plan.tau:.3g}" if plan else ""))
        return out


def report(prototypes, how):
    """The report's "instances" entry: how many instances, each baked prototype's figures, and
    each realised field (role, tree, the objects it was made of; how: name -> role source)."""
    if not prototypes:
        return {"instances": 0, "prototypes": {}, "realized": {}}
    return {
        "instances": prototypes.count,
        "prototypes": {r.name: {"tree": r.tree, "method": r.method, "vertices": r.vertices,
                                "seconds": r.seconds,
                                "ao_mean": float(r.ao.mean()) if r.vertices else None}
                       for r in prototypes.results},
        "realized": {r.item.name: {"role": r.item.role, "tree": r.item.tree,
                                   "objects": r.objects, "instances": r.instances,
                                   "vertices": len(r.item.positions),
                                   "role_source": how.get(r.item.name, "")}
                     for r in prototypes.realized}}
