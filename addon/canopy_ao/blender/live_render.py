"""Live AO inside a render (F12, Ctrl+F12, ``blender -b … -a``) and in the viewport
(write_viewport): how a frame's AO reaches what is drawn (docs/DESIGN.md, 'Live and per-frame
AO').

A render's depsgraph animates its own copies of the data and never the originals. A tag on an
original makes it copy that original again (and, for a mesh, its shape keys and its object):
whatever animation had set on the copy goes back to the original's values, the frame the
viewport last evaluated. So:
- a target nothing keys (no action, driver or NLA track on its object, mesh or shape keys) is
  written as in the viewport, original and tag: the copy made again is the same plus the AO,
  and every engine redraws it;
- a keyed target is written into the render's evaluated mesh, untagged. Its geometry is
  evaluated again each frame when the keys change it (a shape key, a modifier's value); when
  they do not (only its transform is keyed: no modifier, no shape key), Eevee, Workbench and
  Cycles with Persistent Data draw the mesh they drew before, so the render says so once.
"""

import sys

import bpy
import numpy as np

from . import mesh_io

_WARNED = set()  # scenes told about keyed targets in an engine that may keep their AO


def forget():
    """A new session, a load or an undo: warn again."""
    _WARNED.clear()


def is_render(depsgraph):
    """True for a render's depsgraph, which animates its own copies of the data."""
    return getattr(depsgraph, "mode", 'VIEWPORT') == 'RENDER'


def _keyed(idb):
    ad = getattr(idb, "animation_data", None) if idb is not None else None
    return ad is not None and (ad.action is not None or len(ad.drivers) > 0
                               or len(ad.nla_tracks) > 0)


def keyed(obj):
    """True when animation data on obj, its mesh or its shape keys may set what a copy made
    again from the original would lose."""
    return _keyed(obj) or _keyed(obj.data) or _keyed(obj.data.shape_keys)


def write_frame(scene, depsgraph, objs, attribute, aos):
    """Write each target's AO {name: float32 (V,)} where this render draws it. The caller has
    checked every target's ownership; a target the render does not hold is skipped."""
    attrs = [mesh_io.evaluated_ao_attribute(obj, depsgraph, attribute) for obj in objs]
    kept = []
    for obj, attr in zip(objs, attrs):
        if attr is None:  # not in this render
            continue
        if keyed(obj):
            mesh_io.write_evaluated_ao(attr, aos[obj.name])
            if mesh_io.evaluated_is_original(obj):  # no modifier or shape key to re-evaluate
                kept.append(obj.name)
        else:
            mesh_io.write_ao_attribute(obj, attribute, aos[obj.name], checked=True)
    engine = scene.render.engine
    if kept and (engine != 'CYCLES' or scene.render.use_persistent_data) \
            and scene.name not in _WARNED:
        _WARNED.add(scene.name)
        print(f"canopy_ao: warning: {', '.join(kept)}: keyed, so live AO goes into the "
              "render's copy, and nothing keyed changes their geometry, so "
              f"{'Cycles with Persistent Data' if engine == 'CYCLES' else engine} keeps its "
              "first frame's AO", file=sys.stderr, flush=True)


def geometry_updated(depsgraph):
    """Names of the objects whose geometry this depsgraph evaluated at its last update (in a
    frame_change_post handler: this frame's)."""
    return {u.id.original.name for u in depsgraph.updates
            if u.is_updated_geometry and isinstance(u.id, bpy.types.Object)}


def _drawn_attribute(obj, depsgraph, attribute):
    """The attribute of obj's evaluated mesh, None where there is none to write (a modifier
    drops it: the original is then written and tagged, as for a still target)."""
    try:
        return mesh_io.evaluated_ao_attribute(obj, depsgraph, attribute)
    except mesh_io.MeshIOError:
        return None


def write_viewport(depsgraph, objs, attribute, aos, last, lagging):
    """Write each target's AO {name: float32 (V,)} where the viewport draws it, evaluating
    nothing again where that can be avoided (docs/DESIGN.md, 'Live and per-frame AO'). The
    caller has checked every target's ownership. last: {name: the AO last written}, updated.
    lagging: {name: (AO, the ownership record its original holds)}, updated: the targets
    whose original is behind what is drawn (Session.flush writes them).

    A target whose geometry this frame evaluated (a deform, a shape key, an armature) has a
    new evaluated mesh that nothing has drawn yet: its attribute is written there, untagged,
    and its original left until a save, a stop or a render needs it (lagging). Tagging it
    instead makes Blender evaluate it a second time in this frame (its modifiers again: as
    long as Blender's own frame). A target not evaluated this frame (a still ground) keeps its
    drawn copy, so its original is written and tagged, and only when its AO changed."""
    from .ownership import recorded
    fresh = geometry_updated(depsgraph)
    for obj in objs:
        ao = aos[obj.name]
        attr = _drawn_attribute(obj, depsgraph, attribute) if obj.name in fresh else None
        if attr is not None:
            mesh_io.write_evaluated_ao(attr, ao)
            held = lagging.get(obj.name)
            lagging[obj.name] = (ao, held[1] if held else recorded(obj.data, attribute))
        elif obj.name not in last or not np.array_equal(last[obj.name], ao):
            mesh_io.write_ao_attribute(obj, attribute, ao, checked=True)
            lagging.pop(obj.name, None)
        last[obj.name] = ao
