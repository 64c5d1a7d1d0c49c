"""The bake loop: the receivers of a bake's targets evaluated under a prepared plan, one chunk
per step, so progress and Esc cover vertices and texels alike. A single bake (job.BakeJob)
steps it between modal ticks or runs it; a frame range (frames.FrameBake) and live AO
(live_session.Session) run it once per frame, on the frame's refitted plan."""

import time

import numpy as np

from .. import core
from ..core import card_carry, maps
from ..core.native import CanopyAOError
from . import bent_io, parts_io
from .targets import chunks, chunks_done, split_chunks
from .texel_target import TexelTarget
from .vertex_target import VertexTarget

# The kind of target for each Output (the option "mode"): targets.Target's interface.
KINDS = {'VERTEX': VertexTarget, 'TEXEL': TexelTarget}


class Loop:
    """The targets' receivers in chunks of about ``size`` (targets.chunks), evaluated one per
    step() once start() has given the plan."""

    def __init__(self, targets, size):
        self.targets = targets
        self.chunks = chunks(targets, size)  # (target, first, last receiver) per step
        self.next = 0  # the next step's index
        self.plan = None
        self.bent, self.thickness, self.means = "OFF", False, {}
        self.cards = False

    def start(self, plan, bent="OFF", thickness=False, means=None, cards=False):
        """Evaluate under ``plan`` from now on. bent: the space of the bent normals to make
        too ("OFF": none); thickness: make the thickness too; means: {prototype name: the
        mean AO of its vertices over its instances} (instances.Prototypes.means); cards: leaf
        cards' vertices carry their opaque part's AO (core/card_ao.py), unless bent normals
        are made (their trace evaluates a card's vertices where they are, as live frames do)."""
        self.plan, self.bent, self.thickness = plan, bent, thickness
        self.means = means or {}
        self.cards = cards and bent == "OFF"

    def split(self, size):
        """Cut the steps still to come to ``size`` receivers where a target allows
        (Target.cut): the same AO in shorter steps."""
        self.chunks[self.next:] = split_chunks(self.chunks[self.next:], size)

    def progress(self):
        """(object, receivers done, receivers in all) before the next step."""
        return chunks_done(self.targets, self.chunks, self.next)

    def step(self):
        """Evaluate the next chunk. Returns (target, seconds, complete), None when every chunk
        is done; complete: the chunk was the target's last (its finish() has run)."""
        if self.next >= len(self.chunks):
            return None
        t, a, b = self.chunks[self.next]
        self.next += 1
        t0 = time.perf_counter()
        bent = self.bent != "OFF"
        try:
            shared = t.shared_ao(self.means)
            if shared is not None:
                # A grass blade instanced over a field: what its instances see, not the lone
                # prototype (instances.Prototypes.bake_realized).
                t.ao[a:b] = shared[a:b]
            elif t.parts:  # a mesh baked by parts: each part's receivers by its item
                t.ao[a:b] = parts_io.evaluate(self.plan, t, a, b, self.cards)
            elif bent and maps.rung_is_the_trace(self.plan, t.item):  # one trace gives both
                t.ao[a:b] = self._bent_step(t, a, b)
            else:
                t.ao[a:b] = core.evaluate_receivers(
                    self.plan, t.item, t.positions[a:b], t.normals[a:b], group=t.group,
                    vertices=t.vertices(a, b), triangles=t.triangles_of(a, b))
                if self.cards:
                    card_carry.carry(self.plan, t.item, t.ao[a:b], t.vertices(a, b))
                if bent:
                    self._bent_step(t, a, b)
        except CanopyAOError as exc:
            raise CanopyAOError(f"{t.item.name}: {exc}") from exc
        if self.thickness:
            if t.thickness is None:
                t.thickness = np.zeros(t.count, np.float32)
            t.thickness[a:b] = maps.thickness(self.plan, t.item, t.positions[a:b],
                                              t.vertices(a, b))
        seconds = time.perf_counter() - t0
        t.seconds += seconds
        if b < t.count:
            return t, seconds, False
        t.finish()
        return t, seconds, True

    def _bent_step(self, t, a, b):
        """Bent normals of receivers a..b of target t, in the space asked for. Returns the
        AO of the same trace (maps.bent_normals)."""
        if t.bent is None:
            t.bent = np.zeros((t.count, 3), np.float32)
        ao, world = maps.bent_normals(self.plan, t.item, t.positions[a:b], t.normals[a:b],
                                      vertices=t.vertices(a, b),
                                      triangles=t.triangles_of(a, b), with_ao=True,
                                      group=t.group)
        frames = (t.frames[0][a:b], t.frames[1][a:b]) if t.frames is not None else None
        t.bent[a:b] = bent_io.in_space(world, t.normals[a:b], self.bent, frames)
        if t.group > 1:  # a texel's sub-samples: each one's share of open rays weighs it
            if t.bent_weight is None:
                t.bent_weight = np.zeros(t.count, np.float32)
            t.bent_weight[a:b] = ao
        return ao

    def run(self):
        """Every step still to come."""
        while self.step() is not None:
            pass
