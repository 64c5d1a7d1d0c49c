"""What a bake writes, one Target per object: its receivers (vertices, or the texels the native
rasteriser finds in its UV layout), the AO evaluated for them, and how that AO is written
(docs/DESIGN.md, 'Data flow'). Reading happens when a target is made, writing only in write().

Target is the interface every kind of target has (vertex_target.VertexTarget,
texel_target.TexelTarget): the bake loop (loop.py) and the job (job.py) call its methods and
never ask which kind a target is. One bake's targets are all of one kind (the bake's Output),
so what concerns all of them at once (their files, their writes, the Cycles check) is a
classmethod taking the list."""

import numpy as np

from ..core.native import CanopyAOError
from . import materials, ownership, parts_io


class Target:
    # The receivers' noun in the report lines ("1 texel", "4 texels"), and its plural.
    kind = ""
    kinds = ""
    # Results per mesh vertex: an instanced prototype's vertices take the mean AO over its
    # instances (instances.Prototypes), and its attribute is written in place when last
    # (commit.Transaction).
    per_vertex = False
    # Results written onto the mesh (an attribute), so several targets may not share one.
    on_mesh = False

    def __init__(self, item, obj, positions, normals):
        self.item, self.obj = item, obj
        self.positions, self.normals = positions, normals
        self.triangles = None  # texels: each one's triangle in the item's mesh (own rays)
        self.ao = np.ones(len(positions), np.float32)
        self.thickness = None  # float32 like ao when the bake also makes the thickness
        self.bent = None  # float32 (N, 3) when the bake also makes bent normals
        self.frames = None  # (tangents, signs) per receiver for tangent-space bent normals
        self.seconds = 0.0
        self.stats = {}
        self.group = 1  # consecutive receivers per result (a texel's sub-samples; finish())
        # [(part item, its vertex indices)] when the object bakes by parts (parts_io.py).
        self.parts = None

    # === Receivers ===========================================================================

    @property
    def count(self):
        return len(self.positions)

    def chunk(self, n):
        """Receivers per chunk near n: whole groups, so no chunk splits a texel's sub-samples
        (their rays are dealt by row within the call)."""
        return max(self.group, n - n % self.group)

    def cut(self, a, b, size):
        """Receivers a..b as chunks of at most ``size`` where any split gives the same AO, else
        whole: [(first, last)]."""
        return [(a, b)]

    def vertices(self, a, b):
        """Receivers a..b as the item's vertices (core.evaluate_receivers' ``vertices``), or
        None when they are not its vertices."""
        return None

    def triangles_of(self, a, b):
        """The triangle each of receivers a..b lies on (their own rays skip it), or None."""
        return self.triangles[a:b] if self.triangles is not None else None

    def shared_ao(self, means):
        """This target's AO when it is a prototype whose instances' mean it takes (means:
        instances.Prototypes.means), else None."""
        return None

    def finish(self):
        """Called once every receiver is evaluated, before the result is reported."""

    # === Writing =============================================================================

    @classmethod
    def attribute(cls, opts):
        """The attribute this kind writes the AO into (the report's), None for images."""
        return None

    @classmethod
    def check_outputs(cls, targets, opts):
        """Refuse, before anything is written, what the targets' writes would clobber."""

    @classmethod
    def write_all(cls, targets, txn, opts, last=False, checked=False):
        """Write every target's results (txn: commit.Transaction). last: nothing that can fail
        follows these writes in the commit; checked: nothing ran between the checks made when
        the targets were read and these writes (a blocking bake). Returns what the report adds
        ({} or more keys)."""
        for t in targets:
            t.write(txn, opts)
        return {}

    def write(self, txn, opts):
        raise NotImplementedError

    # === Reporting ===========================================================================

    def report_into(self, entry, notes):
        """Add this kind's figures to the target's report entry, its warnings to notes (and
        its parts, when it bakes by parts)."""
        if self.parts:
            entry["parts"] = parts_io.summary(self)

    @classmethod
    def check_cycles(cls, context, targets, distance, samples, rep):
        """Compare with Cycles' AO bake of the same receivers, into rep["objects"]."""
        raise NotImplementedError


def chunks(targets, size):
    """(target, first, last receiver) per step of about ``size`` receivers (whole sub-sample
    groups: Target.chunk); an empty target still gets its one step."""
    return [(t, a, min(a + t.chunk(size), t.count)) for t in targets
            for a in range(0, max(t.count, 1), t.chunk(size))]


def split_chunks(steps, size):
    """``steps`` (as chunks() gives) with each chunk cut to ``size`` receivers where its target
    allows (Target.cut)."""
    return [(t, c, d) for t, a, b in steps for c, d in t.cut(a, b, size)]


def chunks_done(targets, steps, k):
    """(object, receivers done, receivers in all) before step k of ``steps``."""
    total = sum(t.count for t in targets)
    if k >= len(steps):
        return "", total, total
    t, a, _b = steps[k]
    return t.item.name, sum(c.count for c in targets[:targets.index(t)]) + a, total


def check_wiring(obj, opts):
    """Refuse, before anything is written, wiring into a material of another .blend file
    (linked, or a library override): the nodes would be lost on save."""
    if not opts["wire_material"]:
        return
    for slot in obj.material_slots:
        why = slot.material is not None and ownership.linked(slot.material)
        if why:
            raise CanopyAOError(
                f"{obj.name}: its material '{slot.material.name}' is {why}, so wiring the AO "
                "into it would be lost on save; make it local (Object > Relations > Make "
                "Local > Selected Objects, Data and Materials) or bake without Wire Material "
                "(nothing was changed)")


def wire_undo(txn, obj):
    """Before wiring obj's materials: when none has our nodes yet, undoing unwires them."""
    mats = [s.material for s in obj.material_slots if s.material is not None]
    if not any(materials.is_ours(n) for m in mats if m.node_tree for n in m.node_tree.nodes):
        txn.add(lambda: materials.unwire(obj))

