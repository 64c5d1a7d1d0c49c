"""A texel target: the AO as an image in the object's UV layout (EXR or another format, a
Blender image, UDIM tiles, an atlas or a packed channel), its thickness and bent normals as
images too, wired into its materials when asked (targets.Target)."""

from types import SimpleNamespace

import bpy
import numpy as np

from ..core.native import CanopyAOError
from . import (bent_io, cycles_check, files_io, gltf_io, maps_io, materials, ownership,
               texel_io, tiles_io)
from .targets import Target, check_wiring, wire_undo


def texel_bent(bent, weight, k):
    """Each texel's bent normal from its k sub-samples' (float32 (k T, 3), unit; each from its
    share of the texel's rays): their mean weighted by the share of their rays that were open
    (weight (k T,), or None: equal), so a sub-sample whose rays were all blocked (its normal
    stands in, raytrace.h 'Bent normals') adds no direction; unit again. Texels whose weighted
    mean is zero (every ray blocked) take the plain mean, then the first sub-sample's."""
    each = np.asarray(bent, np.float64).reshape(-1, k, 3)
    plain = each.mean(axis=1)
    b = plain if weight is None else np.einsum(
        "tk,tki->ti", np.asarray(weight, np.float64).reshape(-1, k), each)
    for alt in (plain, each[:, 0]):
        length = np.linalg.norm(b, axis=1, keepdims=True)
        b = np.where(length > 1e-12, b, alt)
    length = np.linalg.norm(b, axis=1, keepdims=True)
    return (b / np.maximum(length, 1e-30)).astype(np.float32)


def check_shared_materials(targets, opts):
    """Refuse, before anything is written, wiring an object's image into a material another
    object shows (one of its slots, or for an object without materials the one wiring gives
    its mesh): a material holds one image, so the last target wired would show on all of them,
    each through its own UVs. With an Atlas the targets share one image: only objects outside
    the bake count."""
    if not (opts["wire_material"] or opts["gltf"]):
        return
    by_material, by_mesh = {}, {}
    for o in bpy.data.objects:
        if o.type == 'MESH':
            by_mesh.setdefault(o.data.as_pointer(), set()).add(o.name)
            for slot in o.material_slots:
                if slot.material is not None:
                    by_material.setdefault(slot.material.as_pointer(), set()).add(o.name)
    baked = {t.obj.name for t in targets}
    found = []
    for t in targets:
        own = baked if opts["atlas"] else {t.obj.name}
        mats = {s.material.as_pointer(): s.material.name for s in t.obj.material_slots
                if s.material is not None}
        for ptr, name in mats.items():
            others = sorted(by_material[ptr] - own)
            if others:
                found.append(f"{t.obj.name}: material '{name}' is also shown on "
                             f"{', '.join(others)}")
        others = sorted(by_mesh[t.obj.data.as_pointer()] - own) if not mats else []
        if others:
            found.append(f"{t.obj.name}: the material wiring gives its mesh "
                         f"'{t.obj.data.name}' is also shown on {', '.join(others)}")
    if found:
        raise CanopyAOError(f"{'; '.join(found)}; a material shows one image, so each would "
                            "show the last object's AO through its own UVs. Give each object "
                            "its own material (Object > Relations > Make Single User > "
                            "Materials; for a shared mesh, Object Data too), bake the objects "
                            "sharing it together into an Atlas, or bake without Wire Material "
                            "(nothing was changed)")


class TexelTarget(Target):
    """An image in the UV layout: an EXR file and a Blender image, wired when asked."""

    kind = "texel"
    kinds = "texels"

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
        self.bent_weight = None  # each sub-sample's open fraction of its rays (loop.Loop)
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
        if self.bent is not None:
            self.bent = texel_bent(self.bent, self.bent_weight, k)
        self.positions, self.normals = self.rx.positions, self.rx.normals
        self.triangles = None

    @classmethod
    def write_all(cls, targets, txn, opts, last=False, checked=False):
        """Each target's images, or with Atlas one image for every object."""
        if not opts["atlas"]:
            return super().write_all(targets, txn, opts)
        st = tiles_io.write_atlas(targets, txn, opts)
        return {"atlas": {"name": opts["atlas"], "paths": st["paths"],
                          "shared_texels": st["shared_texels"]}}

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

    def report_into(self, entry, notes):
        super().report_into(entry, notes)
        entry["texel"] = self.report()
        notes.extend(self.stats.get("warnings", []))

    @classmethod
    def check_cycles(cls, context, targets, distance, samples, rep):
        """Cycles' AO bake of each target's texels, compared with the image just written
        (every tile of a UDIM or atlas image: tiles_io.check_tiles)."""
        for t in targets:
            if "image_tiles" in t.stats:  # UDIM or atlas
                rep["objects"][t.item.name]["cycles"] = tiles_io.check_tiles(
                    context, t, distance, samples)
            else:
                m = cycles_check.check_texel(context, t.obj, t.stats["image"], t.rx.uv_map,
                                             distance, samples, ours_mask=t.stats["mask"] == 1)
                rep["objects"][t.item.name]["cycles"] = {k: float(v) for k, v in m.items()}

    @classmethod
    def check_outputs(cls, targets, opts):
        """Refuse, before anything is written, image files of this bake that would collide or
        replace a file not Canopy AO's own for that output (files_io.check_outputs), and several
        objects packing into the one Pack Image (each would replace the last one's channel)."""
        packing = [t.obj.name for t in targets if opts["channel"] != "RGBA"]
        if len(packing) > 1:
            raise CanopyAOError(f"{', '.join(packing)} would each pack into channel "
                                f"{opts['channel']} of image '{opts['pack_image']}', each "
                                "replacing the one before; bake them one at a time, into images "
                                "of their own (nothing was changed)")
        out = []
        for t in targets:
            for o in t.outputs(opts):
                path = files_io.image_path(SimpleNamespace(name=o.owner),
                                           opts["image_dir"] or None, [], o.map, make=False,
                                           fmt=opts["image_format"])
                out.append((files_io.tile_path(path, o.tile) if o.tile is not None else path,
                            o))
        files_io.check_outputs(out, opts["overwrite"])
        check_shared_materials(targets, opts)
