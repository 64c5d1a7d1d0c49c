"""Texel image files (docs/DESIGN.md, 'Image formats' and 'Ownership of what a bake writes'):
each format holds the baked values within its quantisation and loads as Non-Color data; a
file belongs to the .blend that baked it, in single bakes and batches; a re-bake replaces its
file atomically, so a kill leaves the old image or the new one and nothing stray."""

import os
import shutil
import signal
import struct
import subprocess
import time

import bpy
import numpy as np
import pytest

from canopy_ao import _core
from canopy_ao.blender import files_io
from canopy_ao.blender.job import run_bake
from canopy_ao.core.native import CanopyAOError
from test_maps import opts, tree  # noqa: F401 (tree: the fixture, a plane under leaves)

# The largest difference a format's storage may make to a value in [0, 1]: half a step of
# its quantisation (half floats: 2^-11 relative, under 2.5e-4 below 1).
TOLERANCE = {"EXR": 0.0, "EXR_HALF": 2.5e-4, "PNG": 0.5 / 255 + 1e-6,
             "PNG16": 0.5 / 65535 + 1e-7, "TGA": 0.5 / 255 + 1e-6}
EXT = {"EXR": ".exr", "EXR_HALF": ".exr", "PNG": ".png", "PNG16": ".png", "TGA": ".tga"}


def _texel(tree, **kw):
    return opts(mode='TEXEL', resolution=32, image_dir=tree["image_dir"], **kw)


def _bytes(path):
    with open(path, "rb") as f:
        return f.read()


def _png_chunks(path):
    """{chunk type: its data} of a PNG file."""
    data, out = _bytes(path)[8:], {}
    while data:
        n, kind = struct.unpack(">I4s", data[:8])
        out[kind.decode()] = data[8:8 + n]
        data = data[12 + n:]
    return out


@pytest.mark.parametrize("fmt", sorted(TOLERANCE))
def test_each_format_holds_the_baked_values_as_non_color_data(tree, fmt):
    job, rep = run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt))
    t = job.targets[0]
    path = rep["objects"]["Ground"]["texel"]["path"]
    assert path.endswith("Ground_CanopyAO" + EXT[fmt])
    baked = t.stats["image"]
    assert baked.min() < 0.9  # the leaves shade the ground: not a flat image
    got = _core.read_image(path)[:, :, 0]
    assert np.abs(got - baked).max() <= TOLERANCE[fmt]
    # Blender's image: that file, Non-Color, the same values (no colour conversion).
    img = bpy.data.images[f"Ground_CanopyAO"]
    assert bpy.path.abspath(img.filepath) == path
    assert img.colorspace_settings.name == "Non-Color"
    w, h = img.size
    px = np.empty(w * h * img.channels, np.float32)
    img.pixels.foreach_get(px)
    assert np.abs(px[0::img.channels].reshape(h, w) - got).max() <= 1e-6
    if fmt.startswith("PNG"):  # linear values, and no chunk claiming sRGB or a gamma
        # Nothing claims an sRGB encoding: no sRGB or ICC chunk, and a gamma, where there is
        # one (OpenImageIO 3 writes it), of 1.0 (gAMA stores 100,000 × the file's gamma).
        chunks = _png_chunks(path)
        assert not {"sRGB", "iCCP"} & set(chunks), sorted(chunks)
        assert struct.unpack(">I", chunks.get("gAMA", b"\x00\x01\x86\xa0"))[0] == 100000
    # The file is the bake's own: a re-bake replaces it without Overwrite.
    run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt, tau=3.0))
    assert sorted(os.listdir(tree["image_dir"])) == [os.path.basename(path)]


@pytest.mark.parametrize("fmt", ["EXR_HALF", "PNG", "PNG16", "TGA"])
def test_each_format_refuses_a_file_that_is_not_the_bakes_own(tree, fmt):
    d = tree["image_dir"]
    path = os.path.join(d, "Ground_CanopyAO" + EXT[fmt])
    user = np.full((8, 8), 0.5, np.float32)
    _core.write_image(path, user, dtype="half" if fmt == "EXR_HALF" else "uint8")
    before = _bytes(path)
    with pytest.raises(CanopyAOError, match="already exists and Canopy AO did not write it"):
        run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt))
    # Canopy AO's file of another object (what a case-insensitive file system would give).
    files_io.write_file(path, user, files_io.Output("Leaves"), fmt)
    ours = _bytes(path)
    with pytest.raises(CanopyAOError, match="holds (Canopy AO's 'CanopyAO' of 'Leaves'|another "
                                            "Canopy AO output)"):
        run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt))
    assert _bytes(path) == ours and before != ours
    run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt, overwrite=True))
    assert files_io.check_file(path, files_io.Output("Ground")) is None
    assert sorted(os.listdir(d)) == [os.path.basename(path)]


def test_every_image_of_a_bake_takes_the_format(tree):
    """Thickness and bent normals in 16-bit PNG, UDIM tiles in half EXR, an atlas in TGA."""
    d = tree["image_dir"]
    run_bake(bpy.context, ["Ground"], _texel(tree, image_format="PNG16", thickness=True,
                                             bent_normals="WORLD"))
    files = ["Ground_CanopyAO.png", "Ground_CanopyBentNormal.png", "Ground_CanopyThickness.png"]
    assert sorted(os.listdir(d)) == files
    bent = _core.read_image(os.path.join(d, "Ground_CanopyBentNormal.png"))
    # Encoded 0.5 + 0.5 b: in [0, 1]; 1.0 where b is the normal (rays summing straight up,
    # or every ray blocked: raytrace.h "Bent normals")
    assert bent.shape == (32, 32, 3) and 0.0 < bent.min() and bent.max() <= 1.0
    assert bent[:, :, 2].min() > 0.5  # the ground's bent normals lean up
    for f in files:
        assert files_io.file_record(os.path.join(d, f))["format"] == "PNG16"
        assert bpy.data.images[f[:-4]].colorspace_settings.name == "Non-Color"
    run_bake(bpy.context, ["Ground"], _texel(tree, image_format="EXR_HALF", udim=True,
                                             thickness=True))
    assert {"Ground_CanopyAO.1001.exr", "Ground_CanopyThickness.1001.exr"} <= set(os.listdir(d))
    assert bpy.data.images["Ground_CanopyAO"].source == 'TILED'
    assert files_io.file_record(os.path.join(d, "Ground_CanopyAO.1001.exr"))["format"] == \
        "EXR_HALF"
    run_bake(bpy.context, ["Ground", "Leaves"], _texel(tree, image_format="TGA",
                                                         atlas="Shared"))
    atlas = os.path.join(d, "Shared_CanopyAO.tga")
    assert files_io.check_file(atlas, files_io.Output("Shared", atlas=True)) is None
    assert files_io.check_file(atlas, files_io.Output("Shared")) is not None


# === Two .blend files in one folder

def test_a_bake_of_another_blend_file_never_replaces_its_image(tree, tmp_path):
    """a.blend and b.blend side by side, each with a 'Ground' baked per texel into
    //canopy_ao: the second bake would replace the image a.blend's material shows."""
    o = dict(_texel(tree), image_dir="//canopy_ao", wire_material=True)
    a, b = str(tmp_path / "a.blend"), str(tmp_path / "b.blend")
    bpy.ops.wm.save_as_mainfile(filepath=a)
    _job, rep = run_bake(bpy.context, ["Ground"], o)
    path = rep["objects"]["Ground"]["texel"]["path"]
    assert path == str(tmp_path / "canopy_ao" / "Ground_CanopyAO.exr")
    bpy.ops.wm.save_as_mainfile(filepath=a)
    first = _bytes(path)
    bpy.ops.wm.save_as_mainfile(filepath=b)
    with pytest.raises(CanopyAOError, match=f"baked from the .blend file '{a}', not from this "
                                            f".blend file \\('{b}'\\)"):
        run_bake(bpy.context, ["Ground"], dict(o, tau=3.0))
    assert _bytes(path) == first and os.listdir(os.path.dirname(path)) == ["Ground_CanopyAO.exr"]
    # Its own file: a.blend re-bakes it (also when the project folder moves as a whole).
    moved = tmp_path / "moved"
    bpy.ops.wm.save_as_mainfile(filepath=a)
    shutil.copytree(tmp_path / "canopy_ao", moved / "canopy_ao")
    bpy.ops.wm.save_as_mainfile(filepath=str(moved / "a.blend"))
    run_bake(bpy.context, ["Ground"], dict(o, tau=3.0))
    assert _bytes(str(moved / "canopy_ao" / "Ground_CanopyAO.exr")) != first
    # b.blend with Overwrite takes the file over.
    bpy.ops.wm.save_as_mainfile(filepath=b)
    run_bake(bpy.context, ["Ground"], dict(o, overwrite=True))
    assert files_io.file_record(path)["blend"] == "../b.blend"


def test_a_batch_never_replaces_another_sources_image(tree, tmp_path, user_scripts):
    """Two sources in one folder baked by the batch into one output folder: both outputs'
    texel images would be OUT/canopy_ao/Ground_CanopyAO.exr. The second is refused (its
    report says why, the task exits 1); the first's image stays what its .blend shows."""
    src = tmp_path / "src"
    src.mkdir()
    for name in ("one", "two"):
        bpy.ops.wm.save_as_mainfile(filepath=str(src / f"{name}.blend"), copy=True)
    out = tmp_path / "out"
    files = [str(src / "one.blend"), str(src / "two.blend")]

    def task(*bake):  # the batch's Blender task (plan.task_command's), both files in one
        return subprocess.run(
            [bpy.app.binary_path, "-b", "--factory-startup", "--addons", "canopy_ao", files[0],
             "--python-expr", "import canopy_ao.batch.worker as w; w.main()", "--", "--root",
             str(src), "--output", str(out), "--files", *files, "--", "--objects", "Ground",
             "--method", "ellipsoid", "--tau", "2", "--mode", "texel", "--resolution", "16",
             "--no-proxies", *bake],
            env=dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts), capture_output=True,
            text=True, timeout=600)
    r = task()
    text = r.stdout + r.stderr
    assert r.returncode != 0, text
    image = out / "canopy_ao" / "Ground_CanopyAO.exr"
    assert f"baked from the .blend file '{out / 'one.blend'}', not from this .blend file " \
           f"('{out / 'two.blend'}')" in text, text[-3000:]
    assert files_io.file_record(str(image))["blend"] == "../one.blend"
    assert sorted(os.listdir(out / "canopy_ao")) == ["Ground_CanopyAO.exr"]
    # A folder per .blend file: both bake.
    r = task("--image-dir", "//canopy_ao/{blend}")
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    for name in ("one", "two"):
        assert files_io.file_record(str(out / "canopy_ao" / name / "Ground_CanopyAO.exr"))[
            "blend"] == f"../../{name}.blend"


# === A kill during a write

KILL_SCRIPT = """
import sys, time
import canopy_ao.cli as c
if sys.argv[-2] == "hold":  # the temporary is written: wait there to be killed
    import canopy_ao.blender.atomic_io as a
    _fsync = a._fsync
    def _held(path, directory=False):
        _fsync(path, directory)
        if not directory:
            time.sleep(60)
    a._fsync = _held
c.main(["--objects", "Ground", "--method", "ellipsoid", "--tau", sys.argv[-1], "--mode",
        "texel", "--resolution", "2048", "--image-dir", "//canopy_ao", "--no-proxies"])
"""


def _cli_bake(blend, user_scripts, tau, wait=True):
    """The command-line bake of blend in a Blender of its own: its exit code and error text,
    or (wait=False) the running process, held once its temporary file is written and flushed
    (just before the rename), so that a kill lands mid-write whatever the machine's load."""
    argv = [bpy.app.binary_path, "-b", blend, "--factory-startup", "--addons", "canopy_ao",
            "--python-exit-code", "1", "--python-expr", KILL_SCRIPT, "--",
            "run" if wait else "hold", str(tau)]
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    if not wait:
        return subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    r = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=300)
    return r.returncode, r.stderr[-2000:]


def test_a_kill_while_the_image_is_written_leaves_the_old_image_and_nothing_stray(
        tree, tmp_path, user_scripts):
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    rc, err = _cli_bake(blend, user_scripts, 2.0)
    assert rc == 0, err
    folder = tmp_path / "canopy_ao"
    path = str(folder / "Ground_CanopyAO.exr")
    old = _core.read_image(path)
    proc = _cli_bake(blend, user_scripts, 3.0, wait=False)  # killed as its temporary appears
    seen = []
    deadline = time.monotonic() + 240
    while proc.poll() is None and not seen and time.monotonic() < deadline:
        seen = [f for f in os.listdir(folder) if f != "Ground_CanopyAO.exr"]
        if not seen:
            time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert seen and ".canopy_ao-tmp." in seen[0], (seen, proc.returncode)
    assert proc.returncode == -signal.SIGKILL
    # The image is there, whole: the old one (the rename had not happened) or the new one.
    now = _core.read_image(path)
    assert now.shape == old.shape and np.all(np.isfinite(now))
    assert files_io.file_record(path) is not None  # intact: its pixels match its record
    # The killed write's temporary is the only thing beside it, and the next bake removes it.
    assert set(os.listdir(folder)) <= {"Ground_CanopyAO.exr", seen[0]}
    rc, err = _cli_bake(blend, user_scripts, 3.0)
    assert rc == 0, err
    assert os.listdir(folder) == ["Ground_CanopyAO.exr"]
    assert not np.array_equal(_core.read_image(path), old)


def test_a_bake_removes_only_the_temporaries_of_writers_that_are_gone(tree):
    """A killed write's temporary (its process gone) goes with the next write of that path;
    one of a process still running (another bake writing now) stays, as do other files."""
    from canopy_ao.blender import atomic_io
    d = tree["image_dir"]
    path = os.path.join(d, "Ground_CanopyAO.exr")
    gone = subprocess.Popen(["true"])
    gone.wait()
    stale = atomic_io.temp_path(path).replace(f".{os.getpid()}.", f".{gone.pid}.")
    live = atomic_io.temp_path(path).replace(f".{os.getpid()}.", ".1.")  # init: always running
    other = os.path.join(d, ".Ground_CanopyAO.exr.notes")
    for f in (stale, live, other):
        with open(f, "wb") as fh:
            fh.write(b"partial")
    run_bake(bpy.context, ["Ground"], _texel(tree))
    assert sorted(os.listdir(d)) == sorted(["Ground_CanopyAO.exr", os.path.basename(live),
                                            os.path.basename(other)])


def test_a_failed_re_bake_puts_the_old_files_back_and_leaves_nothing_else(tree, monkeypatch):
    """The old bytes a rollback needs are held in memory: a bake that fails after writing its
    files (here, while wiring the material) puts each one back, in every format."""
    from canopy_ao.blender import materials
    d = tree["image_dir"]
    run_bake(bpy.context, ["Ground"], _texel(tree, image_format="TGA", thickness=True))
    before = {f: _bytes(os.path.join(d, f)) for f in os.listdir(d)}
    assert sorted(before) == ["Ground_CanopyAO.tga", "Ground_CanopyThickness.tga"]

    def broken(*_a, **_k):
        raise RuntimeError("wiring failed")
    monkeypatch.setattr(materials, "wire_texel_ao", broken)
    with pytest.raises(RuntimeError, match="wiring failed"):
        run_bake(bpy.context, ["Ground"], _texel(tree, image_format="TGA", thickness=True,
                                                 tau=3.0, wire_material=True))
    assert {f: _bytes(os.path.join(d, f)) for f in os.listdir(d)} == before
    # A first bake that fails leaves no file at all.
    with pytest.raises(RuntimeError, match="wiring failed"):
        run_bake(bpy.context, ["Ground"], _texel(tree, image_format="PNG", wire_material=True))
    assert {f: _bytes(os.path.join(d, f)) for f in os.listdir(d)} == before


def test_a_file_whose_record_names_no_blend_file_needs_overwrite_once(tree):
    """An older Canopy AO's EXR (record without the .blend): whose .blend it is cannot be
    told, so it is refused, saying so, until Overwrite takes it over."""
    import json
    from canopy_ao.core.fingerprint import fingerprint
    d = tree["image_dir"]
    path = os.path.join(d, "Ground_CanopyAO.exr")
    img = np.full((8, 8), 0.5, np.float32)
    old = {"owner": "Ground", "map": "CanopyAO", "tile": None, "atlas": False,
           "pixels": fingerprint(img, "pixels")}
    _core.write_image(path, img, attributes={files_io.FILE_RECORD: json.dumps(old)})
    assert files_io.file_record(path) is not None  # a true record, of the older kind
    with pytest.raises(CanopyAOError, match="a .blend file it did not record"):
        run_bake(bpy.context, ["Ground"], _texel(tree))
    run_bake(bpy.context, ["Ground"], _texel(tree, overwrite=True))
    run_bake(bpy.context, ["Ground"], _texel(tree, tau=3.0))  # now its own


@pytest.mark.parametrize("fmt", ["EXR", "PNG"])
def test_an_image_painted_in_blender_and_not_saved_is_refused_without_overwrite(tree, fmt):
    """A re-bake reloads its image from the file: unsaved paint on it would go unasked."""
    run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt, wire_material=True))
    img = bpy.data.images["Ground_CanopyAO"]
    assert not img.is_dirty
    path = bpy.path.abspath(img.filepath)
    before = _bytes(path)
    paint = np.full(len(img.pixels), 0.1, np.float32)
    img.pixels.foreach_set(paint)
    img.pixels.foreach_get(paint)  # as the image holds it (8 bits in a PNG's)
    with pytest.raises(CanopyAOError, match="changes not saved"):
        run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt, wire_material=True,
                                                 tau=3.0))
    assert _bytes(path) == before
    got = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(got)
    assert np.abs(got - paint).max() < 1e-6  # the paint is still there
    run_bake(bpy.context, ["Ground"], _texel(tree, image_format=fmt, wire_material=True,
                                             tau=3.0, overwrite=True))
    assert _bytes(path) != before and not img.is_dirty
