"""What a bake writes, one Target per object: its receivers (vertices, or the texels the native
rasteriser finds in its UV layout), the AO evaluated for them, and how that AO is written
(docs/DESIGN.md, 'Data flow'). Reading happens when a target is made, writing only in write()."""

import bpy
import numpy as np

from . import files_io
from ..core.native import CanopyAOError
from . import bent_io, gltf_io, maps_io, materials, mesh_io, ownership, texel_io, tiles_io


class Target:
    kind = ""

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

    @property
    def count(self):
        return len(self.positions)

    def chunk(self, n):
        """Receivers per chunk near n: whole groups, so no chunk splits a texel's sub-samples
        (their rays are dealt by row within the call)."""
        return max(self.group, n - n % self.group)

    def finish(self):
        """Called once every receiver is evaluated, before the result is reported."""

    def write(self, txn, opts):
        raise NotImplementedError


def chunks(targets, size):
    """(target, first, last receiver) per step of about ``size`` receivers (whole sub-sample
    groups: Target.chunk); an empty target still gets its one step."""
    return [(t, a, min(a + t.chunk(size), t.count)) for t in targets
            for a in range(0, max(t.count, 1), t.chunk(size))]


def split_vertex_chunks(steps, size):
    """``steps`` (as chunks() gives) with each vertex chunk cut to ``size`` receivers: a
    vertex's rays follow its id, so any split gives the same AO (a texel's follow its index
    in the call, so texel chunks stay as they are)."""
    out = []
    for t, a, b in steps:
        n = size if t.kind == "vertex" else max(b - a, 1)
        out.extend((t, c, min(c + n, b)) for c in range(a, max(b, a + 1), n))
    return out


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
    if not any(n.get(materials.TAG) for m in mats if m.node_tree for n in m.node_tree.nodes):
        txn.add(lambda: materials.unwire(obj))


class VertexTarget(Target):
    """A color attribute per vertex."""

    kind = "vertex"

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


class TexelTarget(Target):
    """An image in the UV layout: an EXR file and a Blender image, wired when asked."""

    kind = "texel"

    def __init__(self, item, obj, opts, depsgraph):
        if opts["channel"] != "RGBA" and (opts["udim"] or opts["atlas"]):
            raise CanopyAOError("a channel is packed into one image of one object's 0–1 tile; "
                                "turn off UDIM Tiles and Atlas to pack (nothing was changed)")
        if opts["bent_normals"] != "OFF" and (opts["udim"] or opts["atlas"]):
            raise CanopyAOError("bent normals per texel go into one image of one object's 0–1 "
                                "tile; turn off UDIM Tiles and Atlas, or bake them per vertex "
                                "(nothing was changed)")
        check_wiring(obj, opts)
        self.rx = texel_io.receivers(obj, depsgraph, opts["uv_map"] or None,
                                     opts["resolution"], opts["margin"], opts["udim"],
                                     opts["texel_aa"])
        # Anti-aliased: the receivers are the texels' sub-samples, each casting its share of
        # a texel's rays, averaged back to texels by finish() (texel_points.subsamples).
        pos, nrm, tris = self.rx.sub or (self.rx.positions, self.rx.normals,
                                         self.rx.triangles)
        super().__init__(item, obj, pos, nrm)
        self.group = self.rx.aa ** 2
        # The raster's loop triangles are the item's own when the counts agree (the same
        # evaluated mesh): then a texel's rays skip only its own triangle, as Cycles' do.
        if tris is not None and self.rx.stats.get("triangles") == len(item.triangles):
            self.triangles = tris
        if opts["bent_normals"] == "TANGENT":
            tangents, signs = bent_io.texel_frames(obj, depsgraph, self.rx)
            self.frames = (np.repeat(tangents, self.group, axis=0),
                           np.repeat(signs, self.group, axis=0))
        if opts["gltf"] and opts["udim"]:
            raise CanopyAOError("For glTF wires one image per material; glTF has no UDIM "
                                "tiles: turn off UDIM Tiles (nothing was changed)")
        why = gltf_io.check(obj) if opts["gltf"] else None
        if why:
            raise CanopyAOError(why)
        if opts["channel"] != "RGBA":
            what = (f"Packing {opts['packing']}" if opts["packing"] != "NONE"
                    else f"Channel {opts['channel']}")
            self.pack = bpy.data.images.get(opts["pack_image"])
            if self.pack is None:
                raise CanopyAOError(f"{what} per texel packs into an existing image: no image "
                                    f"named '{opts['pack_image']}'; set Pack Image "
                                    "(nothing was changed)")
            why = maps_io.check_pack_image(self.pack, opts["resolution"], opts["channel"])
            if why:
                raise CanopyAOError(f"{what} of '{obj.name}': {why} (nothing was changed)")
            why = ownership.linked(self.pack)
            if why:  # its pixels would be lost on save, or saved into the library's file
                raise CanopyAOError(f"{obj.name}: Pack Image '{self.pack.name}' is {why}; "
                                    "make it local (or pick a local image) to pack into it "
                                    "(nothing was changed)")

    def finish(self):
        """Every sub-sample evaluated: each texel's AO (and thickness, bent normal) is the mean
        of its sub-samples', and the receivers are the texels again."""
        k = self.group
        if k == 1 or len(self.ao) == len(self.rx.pixels):
            return
        self.ao = self.ao.reshape(-1, k).mean(axis=1, dtype=np.float64).astype(np.float32)
        if self.thickness is not None:
            self.thickness = self.thickness.reshape(-1, k).mean(axis=1).astype(np.float32)
        if self.bent is not None:  # unit again; sub-samples that cancel keep the first's
            each = self.bent.reshape(-1, k, 3)
            b = each.mean(axis=1)
            length = np.linalg.norm(b, axis=1, keepdims=True)
            self.bent = np.where(length > 0, b / np.maximum(length, 1e-30),
                                 each[:, 0]).astype(np.float32)
        self.positions, self.normals = self.rx.positions, self.rx.normals
        self.triangles = None

    def write(self, txn, opts):
        if opts["channel"] != "RGBA":
            img, mask = texel_io.splat(self.rx.pixels, self.ao, self.rx.resolution,
                                       self.rx.resolution, self.rx.margin)
            image = maps_io.pack_image_channel(self.pack, img, opts["channel"], txn)
            self.stats = dict(self.rx.stats, image=img, mask=mask, path=image.filepath,
                              packed_into=image.name, channel=opts["channel"])
        elif opts["udim"]:
            image, st = tiles_io.write_tiled(self.obj, [(self.rx, self.ao)],
                                             opts["image_dir"] or None, txn, tiled=True,
                                             overwrite=opts["overwrite"],
                                             fmt=opts["image_format"])
            self.stats = dict(self.rx.stats, path=st["paths"][0], paths=st["paths"],
                              tiles=sorted(st["tiles"]), image_tiles=st["tiles"],
                              notes=self.rx.stats["notes"] + st["notes"])
        else:
            image, self.stats = texel_io.write_texels(self.obj, self.rx, self.ao,
                                                      opts["image_dir"] or None, txn,
                                                      overwrite=opts["overwrite"],
                                                      fmt=opts["image_format"])
        timage = None
        if self.thickness is not None and opts["udim"]:
            timage, tstats = tiles_io.write_tiled(self.obj, [(self.rx, self.thickness)],
                                                  opts["image_dir"] or None, txn,
                                                  suffix=opts["thickness_name"], tiled=True,
                                                  background=0.0, overwrite=opts["overwrite"],
                                                  fmt=opts["image_format"])
            self.stats["thickness_path"] = tstats["paths"][0]
        elif self.thickness is not None:
            timage, tstats = texel_io.write_texels(self.obj, self.rx, self.thickness,
                                                   opts["image_dir"] or None, txn,
                                                   suffix=opts["thickness_name"],
                                                   background=0.0, overwrite=opts["overwrite"],
                                                   fmt=opts["image_format"])
            self.stats["thickness_path"] = tstats["path"]
        if self.bent is not None:
            _img, path, notes = bent_io.write_image(self.obj, self.rx, self.bent,
                                                    opts["bent_normals"],
                                                    opts["image_dir"] or None, txn,
                                                    opts["bent_normals_name"],
                                                    opts["overwrite"], opts["image_format"])
            self.stats["bent_normals_path"] = path
            said = self.stats.setdefault("notes", [])
            said += [n for n in notes if n not in said]  # the AO's image may have said it
        self.wire(txn, opts, image, timage)

    def outputs(self, opts):
        """files_io.Output of every image file write() makes: the AO's, the thickness's and the
        bent normals', per UDIM tile (tile None: one file), the atlas's when baking into one."""
        if opts["channel"] != "RGBA":
            return []  # packed into the user's chosen image (the ask is choosing it)
        owner = opts["atlas"] if opts["atlas"] else self.obj.name
        tiles = [n for n, _a, _b in self.rx.tiles] if opts["udim"] else [None]
        maps = (["CanopyAO"] + ([opts["thickness_name"]] if opts["thickness"] else [])
                + ([opts["bent_normals_name"]] if opts["bent_normals"] != "OFF" else []))
        return [files_io.Output(owner, m, n, bool(opts["atlas"])) for m in maps for n in tiles]

    def wire(self, txn, opts, image, timage):
        """Wire the AO image (and the thickness's, timage) into obj's materials when asked."""
        if opts["wire_material"]:
            wire_undo(txn, self.obj)
            if opts["channel"] == "RGBA":
                self.stats["nodes_added"] = materials.wire_texel_ao(
                    self.obj, image, self.rx.uv_map, opts["aov_name"])
            if self.thickness is not None:
                maps_io.wire_thickness(self.obj, "texel", timage, opts["thickness_name"],
                                       self.rx.uv_map)
        if opts["gltf"]:
            wire_undo(txn, self.obj)
            gltf_io.wire_occlusion(self.obj, image, opts["channel"], self.rx.uv_map, txn)

    def report(self):
        """The texel stats as plain data for the JSON report."""
        return {k: v for k, v in self.stats.items() if isinstance(v, (int, float, str, list))}


def check_outputs(targets, opts):
    """Refuse, before anything is written, image files of this bake that would collide or
    replace a file not Canopy AO's own for that output (files_io.check_outputs), and several
    objects packing into the one Pack Image (each would replace the last one's channel)."""
    from types import SimpleNamespace
    packing = [t.obj.name for t in targets if t.kind == "texel" and opts["channel"] != "RGBA"]
    if len(packing) > 1:
        raise CanopyAOError(f"{', '.join(packing)} would each pack into channel "
                            f"{opts['channel']} of image '{opts['pack_image']}', each replacing "
                            "the one before; bake them one at a time, into images of their own "
                            "(nothing was changed)")
    out = []
    for t in targets:
        if t.kind != "texel":
            continue
        for o in t.outputs(opts):
            path = files_io.image_path(SimpleNamespace(name=o.owner), opts["image_dir"] or None,
                                       [], o.map, make=False, fmt=opts["image_format"])
            out.append((files_io.tile_path(path, o.tile) if o.tile is not None else path, o))
    files_io.check_outputs(out, opts["overwrite"])
