"""What Cycles renders, so what occludes in its AO bake: one home for the rules (docs/DESIGN.md,
'What occludes', where each was measured with a Cycles AO bake). Nothing here changes the scene.

- An object renders when it is not disabled in renders and some path of collections from the
  view layer reaches it with no collection disabled in renders and none excluded from the
  view layer (an object linked into two collections renders if either path does).
- Viewport hiding (eye, monitor; object, collection or layer collection) does not matter:
  Cycles' bake renders those objects.
- AO rays are shadow rays: an object with Ray Visibility > Shadow off does not occlude; camera,
  diffuse, glossy, transmission and volume visibility, holdout, indirect-only and shadow
  catcher do not change what occludes.
- An instancer's own mesh renders with Show Instancer (for renders). Its instances render when
  the instancer renders and casts shadows, and the instanced object casts shadows; a collection
  instance leaves out objects disabled in renders and collections (the instanced one included)
  disabled in renders, while a particle instance of an object disabled in renders renders.
- A target (an object the bake writes) follows the same rules: one that does not render or
  casts no shadow is refused (gather.bake_targets), as Cycles refuses to bake the first and
  lets the second's own rays through it.
"""

_INSTANCE_TYPES_WITH_COLLECTIONS = ('COLLECTION',)


def casts_shadow(obj):
    """Ray Visibility > Shadow (Object.visible_shadow, Blender 3.0 on)."""
    return bool(getattr(obj, "visible_shadow", True))


def _reach(layer_collection, out):
    """Add to out the pointers of the objects a render reaches through this layer collection."""
    if layer_collection.exclude or layer_collection.collection.hide_render:
        return
    out.update(o.as_pointer() for o in layer_collection.collection.objects)
    for child in layer_collection.children:
        _reach(child, out)


def _reach_collection(collection, out):
    """Add to out the pointers of the objects an instance of collection renders."""
    if collection.hide_render:
        return
    out.update(o.as_pointer() for o in collection.objects if not o.hide_render)
    for child in collection.children:
        _reach_collection(child, out)


class RenderVisibility:
    """The render visibility of one view layer's objects (built once per bake)."""

    def __init__(self, view_layer):
        self._rendered = set()
        _reach(view_layer.layer_collection, self._rendered)
        self._in_layer = set()
        self._all(view_layer.layer_collection, self._in_layer)
        # collection pointer -> (pointers of the objects an instance renders, of all its objects)
        self._instanced = {}
        self._memo = {}  # (object, instancer) pointers -> instance_renders

    def _all(self, layer_collection, out):
        out.update(o.as_pointer() for o in layer_collection.collection.objects)
        for child in layer_collection.children:
            self._all(child, out)

    def object_renders(self, obj):
        """True when Cycles renders obj (a scene object) and its shadow rays can hit it."""
        return (not obj.hide_render and obj.as_pointer() in self._rendered
                and casts_shadow(obj))

    def mesh_renders(self, obj):
        """object_renders, and for an instancer (vertices, faces) or a particle emitter (hair
        too: Blender's BKE_object_visibility) its own mesh shown in renders (Show Instancer,
        Show Emitter)."""
        return self.object_renders(obj) and (not (obj.is_instancer or len(obj.particle_systems))
                                             or obj.show_instancer_for_render)

    def instance_renders(self, obj, instancer):
        """True when an instance of obj (an original object) made by instancer (an original
        object, or None) occludes in Cycles."""
        key = (obj.as_pointer(), instancer.as_pointer() if instancer is not None else 0)
        if key not in self._memo:
            self._memo[key] = self._instance_renders(obj, instancer)
        return self._memo[key]

    def _instance_renders(self, obj, instancer):
        if not casts_shadow(obj):
            return False
        if instancer is None:
            return True
        if instancer.as_pointer() in self._in_layer and not self.object_renders(instancer):
            return False  # a scene object (not one itself instanced) that does not render
        if not casts_shadow(instancer):
            return False
        coll = instancer.instance_collection
        if instancer.instance_type in _INSTANCE_TYPES_WITH_COLLECTIONS and coll is not None:
            ckey = coll.as_pointer()
            if ckey not in self._instanced:
                rendered = set()
                _reach_collection(coll, rendered)
                self._instanced[ckey] = (rendered, {o.as_pointer() for o in coll.all_objects})
            rendered, members = self._instanced[ckey]
            # An object only reached through a nested instance is judged by its own flags.
            ptr = obj.as_pointer()
            if ptr not in rendered and (ptr in members or obj.hide_render):
                return False
        return True
