"""One bake pipeline: targets yield receivers (vertices or texels), step() evaluates them in
chunks, commit() writes everything or nothing, and the Cycles check follows the receivers."""
import os

import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao.blender import job as job_mod, mesh_io, properties
from canopy_ao.blender.job import BakeJob, run_bake
from canopy_ao.core import cost


@pytest.fixture
def plane_under_disk(tmp_path):
    """A UV-mapped ground plane (Ground, 16 x 16 quads) under a disk of leaves (Leaves)."""
    H.empty_scene()
    ground = H.add_plane(size=4.0, subdivisions=15, name="Ground")
    bpy.ops.mesh.primitive_circle_add(vertices=48, radius=1.2, fill_type="NGON",
                                      location=(0, 0, 1.0))
    return H.leaves_over_ground(ground, bpy.context.object, tmp_path)


def _read(path):
    with open(path, "rb") as f:
        return f.read()


def opts(**kw):
    base = dict(properties.scene_options(bpy.context.scene), method="ellipsoid", tau=2.0,
                distance=0.0, show_proxies=False)
    base.update(kw)
    return base


def test_texel_bake_evaluates_texels_in_chunks_and_checks_them_with_cycles(
        plane_under_disk, monkeypatch):
    monkeypatch.setattr(job_mod, "CHUNK", 1000)
    job = BakeJob(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=64,
                                                 image_dir=plane_under_disk["image_dir"],
                                                 check_cycles=True, cycles_samples=16))
    (target,) = job.targets
    texels, receivers = len(target.rx.pixels), target.count
    assert target.kind == "texel" and texels > 3000  # most of the 64 x 64 square
    assert receivers == 4 * texels  # each texel's 2 x 2 anti-aliasing sub-samples (default)
    assert job.steps == 1 + -(-receivers // 1000)  # prepare, then one step per chunk
    job.prepare()
    # Auto's cost model counts what the bake evaluates: Ground's texels' sub-samples, not the
    # leaves' vertices; four to a texel (whose rays they share: cost.corners).
    assert job.plan.targets == {"Ground": ("texel", receivers, 4)}
    assert cost.receiver_count(job.plan, job.items) == receivers
    lines = []
    while (line := job.step()) is not None:
        lines.append(line)
    assert lines[:-1] == [""] * (len(lines) - 1) and f"{texels} texels" in lines[-1]
    assert job.steps_done == job.steps
    rep = job.commit(bpy.context)
    e = rep["objects"]["Ground"]
    assert e["texel"]["texels"] == texels and os.path.exists(e["texel"]["path"])
    # the check compares texels (Cycles' coverage within ours), not vertices
    assert e["cycles"]["n"] > 0.9 * texels and e["cycles"]["n"] != e["vertices"]
    assert "CanopyAO" not in plane_under_disk["ground"].data.attributes  # no vertex write
    # the same model checked per vertex of the same plane errs about as much
    _j, vrep = run_bake(bpy.context, ["Ground"], opts(check_cycles=True, cycles_samples=16))
    v = vrep["objects"]["Ground"]["cycles"]
    assert v["n"] == e["vertices"] == 17 * 17
    assert abs(e["cycles"]["mae"] - v["mae"]) < 0.05, (e["cycles"]["mae"], v["mae"])


def test_chunks_give_the_same_ao_as_one_call(plane_under_disk, monkeypatch):
    _j, one = run_bake(bpy.context, ["Ground"], opts(attribute="One"))
    monkeypatch.setattr(job_mod, "CHUNK", 7)
    _j, many = run_bake(bpy.context, ["Ground"], opts(attribute="Many"))
    g = plane_under_disk["ground"]
    np.testing.assert_array_equal(mesh_io.read_ao_attribute(g, "One"),
                                  mesh_io.read_ao_attribute(g, "Many"))


def test_a_failure_during_commit_writes_nothing(plane_under_disk, monkeypatch):
    """The second object's write fails: the first object's new attribute goes, and an
    attribute of ours that the bake replaced gets its old values back."""
    g, l = plane_under_disk["ground"], plane_under_disk["leaves"]
    run_bake(bpy.context, ["Ground"], opts(tau=0.5))
    before = mesh_io.read_ao_attribute(g, "CanopyAO")
    marks = mesh_io.owned_attributes(g)
    real = mesh_io.write_ao_attribute

    def second_fails(obj, name, ao, overwrite=False, checked=False):
        if obj.name == "Leaves":
            raise RuntimeError("disk full, say")
        return real(obj, name, ao, overwrite)

    monkeypatch.setattr(mesh_io, "write_ao_attribute", second_fails)
    job = BakeJob(bpy.context, ["Ground", "Leaves"], opts(tau=3.0))
    assert [t.item.name for t in job.targets] == ["Ground", "Leaves"]
    job.run()
    with pytest.raises(RuntimeError, match="disk full"):
        job.commit(bpy.context)
    np.testing.assert_array_equal(mesh_io.read_ao_attribute(g, "CanopyAO"), before)
    assert mesh_io.owned_attributes(g) == marks
    assert "CanopyAO" not in l.data.attributes and not mesh_io.owned_attributes(l)


def test_the_last_write_copies_nothing_and_a_failure_in_it_still_changes_nothing(
        plane_under_disk, monkeypatch):
    """One vertex target and nothing after it in the commit: its attribute is overwritten in
    place without a copy of the old values (16 bytes a vertex), while a Cycles check after it
    keeps the copy; a write that fails leaves the old values and marks."""
    from canopy_ao.blender import commit
    g = plane_under_disk["ground"]
    run_bake(bpy.context, ["Ground"], opts(tau=0.5))
    before = mesh_io.read_ao_attribute(g, "CanopyAO")
    marks = mesh_io.owned_attributes(g)
    copies = []
    real_attribute = commit.Transaction.attribute

    def spy(self, obj, name, last=False):
        attr = obj.data.attributes.get(name)
        copies.append((name, last, attr is not None and not (
            last and attr.data_type == 'FLOAT_COLOR' and attr.domain == 'POINT')))
        return real_attribute(self, obj, name, last)
    monkeypatch.setattr(commit.Transaction, "attribute", spy)
    run_bake(bpy.context, ["Ground"], opts(tau=3.0))
    assert copies == [("CanopyAO", True, False)]  # last, in place: no copy
    changed = mesh_io.read_ao_attribute(g, "CanopyAO")
    assert not np.array_equal(changed, before)
    copies.clear()
    run_bake(bpy.context, ["Ground"], opts(tau=3.0, check_cycles=True, cycles_samples=4))
    assert copies == [("CanopyAO", False, True)]  # the check follows: old values kept

    def fails(obj, name, ao, overwrite=False, checked=False):
        raise RuntimeError("disk full, say")
    monkeypatch.setattr(mesh_io, "write_ao_attribute", fails)
    with pytest.raises(RuntimeError, match="disk full"):
        run_bake(bpy.context, ["Ground"], opts(tau=0.5))
    np.testing.assert_array_equal(mesh_io.read_ao_attribute(g, "CanopyAO"), changed)
    assert mesh_io.owned_attributes(g) == marks


def test_a_failed_texel_commit_leaves_no_image_and_keeps_the_old_file(plane_under_disk,
                                                                      monkeypatch):
    d = plane_under_disk["image_dir"]
    _j, rep = run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=16, image_dir=d))
    path = rep["objects"]["Ground"]["texel"]["path"]
    old = _read(path)
    n_images = len(bpy.data.images)

    def fails(*a, **k):
        raise RuntimeError("the check broke")

    monkeypatch.setattr(job_mod.BakeJob, "_check_cycles", fails)
    with pytest.raises(RuntimeError, match="the check broke"):
        run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=32, image_dir=d,
                                                 check_cycles=True, tau=0.3))
    assert _read(path) == old and len(bpy.data.images) == n_images
    assert sorted(os.listdir(d)) == [os.path.basename(path)]  # no backup left behind
