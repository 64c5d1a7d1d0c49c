"""The batch planner's pure logic (canopy_ao.batch.plan): inputs, output paths, resume, task
command lines, summary. No Blender: files are stand-ins with the right names."""

import csv
import json
import os
import time

import pytest

from canopy_ao.batch import plan
from canopy_ao.batch.__main__ import build_parser, split_argv


def _touch(path, text="x", mtime=None):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)
    if mtime is not None:
        os.utime(path, ns=(mtime, mtime))
    return path


@pytest.fixture
def tree(tmp_path):
    """in/a.blend, in/sub/b.blend, in/sub/deep/c.blend, in/notes.txt, in/a.blend1."""
    d = tmp_path / "in"
    files = [_touch(str(d / p)) for p in ("a.blend", "sub/b.blend", "sub/deep/c.blend")]
    _touch(str(d / "notes.txt"))
    _touch(str(d / "a.blend1"))
    return tmp_path, files


def test_inputs_from_folders_globs_files_and_manifest_in_order_once(tree):
    tmp, (a, b, c) = tree
    d = str(tmp / "in")
    assert plan.expand_inputs([d]) == [a]  # a folder: its own *.blend, not .blend1 or .txt
    assert plan.expand_inputs([os.path.join(d, "**", "*.blend")]) == [a, b, c]
    assert plan.expand_inputs([c, a, c]) == [c, a]
    manifest = _touch(str(tmp / "list.txt"),
                      "# files to bake\nin/sub/deep/c.blend\n\n" + a + "  # absolute\nin/sub/*.blend\n")
    assert plan.expand_inputs(plan.read_manifest(manifest)) == [c, a, b]


def test_a_folder_named_like_a_blend_file_is_no_input(tree):
    """A folder `x.blend` beside the files (an unpacked asset, say) is not baked: a Blender
    started on it could only fail, twice with the retry."""
    tmp, (a, b, c) = tree
    d = str(tmp / "in")
    os.makedirs(os.path.join(d, "folder.blend"))
    os.makedirs(os.path.join(d, "sub", "deep", "more.blend"))
    assert plan.expand_inputs([d]) == [a]
    assert plan.expand_inputs([os.path.join(d, "**", "*.blend")]) == [a, b, c]
    with pytest.raises(plan.BatchError, match="no .blend file matches"):
        plan.expand_inputs([os.path.join(d, "fold*.blend")])


@pytest.mark.parametrize("entry, message", [
    ("missing.blend", "no such file"), ("*.nothing", "no .blend file matches"),
    ("in/notes.txt", "is not a .blend"), ("empty", "has no .blend file")])
def test_bad_inputs_say_what_is_wrong(tree, entry, message):
    tmp, _ = tree
    os.makedirs(tmp / "empty", exist_ok=True)
    with pytest.raises(plan.BatchError, match=message):
        plan.expand_inputs([str(tmp / entry)])
    with pytest.raises(plan.BatchError, match="cannot read the manifest"):
        plan.read_manifest(str(tmp / "nope.txt"))
    with pytest.raises(plan.BatchError, match="no .blend files given"):
        plan.expand_inputs([])


def test_outputs_mirror_the_layout_below_the_common_folder(tree):
    tmp, (a, b, c) = tree
    root = plan.common_root([a, b, c])
    assert root == str(tmp / "in")
    out = str(tmp / "out")
    assert plan.output_path(c, root, out) == os.path.join(out, "sub", "deep", "c.blend")
    assert plan.report_path(c, root, out) == os.path.join(out, "sub", "deep", "c.canopy_ao.json")
    assert plan.output_path(c, root, out, in_place=True) == c
    assert plan.common_root([b]) == str(tmp / "in" / "sub")


def test_outputs_never_overwrite_sources_unless_in_place(tree):
    tmp, files = tree
    root = plan.common_root(files)
    with pytest.raises(plan.BatchError, match="would overwrite it"):
        plan.check_outputs(files, root, root, in_place=False)
    with pytest.raises(plan.BatchError, match="inside the output folder"):
        plan.check_outputs(files, root, str(tmp), in_place=False)
    plan.check_outputs(files, root, root, in_place=True)
    plan.check_outputs(files, root, str(tmp / "out"), in_place=False)


def test_a_file_at_an_output_path_that_no_report_claims_is_never_replaced(tree):
    """--output pointing at a folder that already holds a file of that name (the user's own,
    or another source's copy): refused before any Blender starts; the batch's own copy, whose
    report names its source, is replaced by a rerun."""
    tmp, (a, b, c) = tree
    root, out = str(tmp / "in"), str(tmp / "out")
    theirs = _touch(os.path.join(out, "sub", "b.blend"), "the user's")
    with pytest.raises(plan.BatchError, match="not a batch's copy of .*b.blend"):
        plan.check_outputs([a, b, c], root, out, False)
    plan.write_report(plan.failed_report(c, theirs, [], 1, "x"), plan.report_path(b, root, out))
    with pytest.raises(plan.BatchError, match="not a batch's copy"):  # another source's report
        plan.check_outputs([a, b, c], root, out, False)
    plan.write_report(plan.failed_report(b, theirs, [], 1, "x"), plan.report_path(b, root, out))
    plan.check_outputs([a, b, c], root, out, False)
    plan.check_outputs([a, b, c], root, out, True)  # in place: the sources are the outputs
    with open(theirs) as f:
        assert f.read() == "the user's"


def test_reserved_bake_options_are_refused():
    plan.check_bake_args(["--method", "sphere", "--objects", "Leaves"])
    for bad in (["--save"], ["--report", "x.json"], ["--threads=2"]):
        with pytest.raises(plan.BatchError, match="set by the batch"):
            plan.check_bake_args(bad)


def _baked(tmp, key, src_mtime, out_mtime, status="ok"):
    src = _touch(str(tmp / "s.blend"), mtime=src_mtime)
    out = _touch(str(tmp / "o" / "s.blend"), mtime=out_mtime)
    rep = str(tmp / "o" / "s.canopy_ao.json")
    plan.write_report(dict(status=status, source=src, output=out, options=key,
                           output_mtime_ns=os.stat(out).st_mtime_ns), rep)
    return src, out, rep


def test_resume_skips_only_a_good_unchanged_result_with_the_same_options(tmp_path):
    key = plan.options_key(["--method", "sphere"])
    t = time.time_ns()
    src, out, rep = _baked(tmp_path, key, t - 10**9, t)
    assert plan.up_to_date(src, out, rep, key) == (True, "up to date")
    assert plan.up_to_date(src, out, rep, plan.options_key(["--method", "grid"]))[1] == \
        "the options changed"
    assert plan.up_to_date(src, out, rep, plan.options_key(["--method", "sphere"], True))[0] \
        is False
    os.utime(src, ns=(t + 10**9, t + 10**9))  # the source was edited after the bake
    assert plan.up_to_date(src, out, rep, key)[1] == "the source is newer than its output"
    os.utime(src, ns=(t - 10**9, t - 10**9))
    os.utime(out, ns=(t + 5, t + 5))  # something else rewrote the output
    assert plan.up_to_date(src, out, rep, key)[1] == "the output was changed since"
    os.remove(out)
    assert plan.up_to_date(src, out, rep, key)[1] == "the output is missing"
    src, out, rep = _baked(tmp_path, key, t - 10**9, t, status="failed")
    assert plan.up_to_date(src, out, rep, key)[1] == "the last bake failed"
    with open(rep, "w") as f:
        f.write("{half a report")
    assert plan.up_to_date(src, out, rep, key)[0] is False
    os.remove(rep)
    assert plan.up_to_date(src, out, rep, key)[0] is False


def test_in_place_result_is_valid_until_the_file_changes(tmp_path):
    key = plan.options_key(["--method", "sphere"], in_place=True)
    src = _touch(str(tmp_path / "s.blend"))
    rep = str(tmp_path / "o" / "s.canopy_ao.json")
    plan.write_report(dict(status="ok", source=src, output=src, options=key,
                           output_mtime_ns=os.stat(src).st_mtime_ns), rep)
    assert plan.up_to_date(src, src, rep, key)[0]
    st = os.stat(src).st_mtime_ns + 10**9
    os.utime(src, ns=(st, st))
    assert not plan.up_to_date(src, src, rep, key)[0]


def test_groups_and_the_task_command_line():
    assert plan.group([1, 2, 3, 4, 5], 2) == [[1, 2], [3, 4], [5]]
    assert plan.group([1], 4) == [[1]]
    with pytest.raises(plan.BatchError):
        plan.group([1], 0)
    cmd = plan.task_command("/opt/blender", ["/r/a.blend", "/r/b.blend"], "/r", "/o",
                            ["--method", "sphere"], threads=2, in_place=True)
    assert cmd == ["/opt/blender", "-b", "--factory-startup", "--addons", "canopy_ao",
                   "--python-exit-code", "1", "/r/a.blend", "--python-expr", plan.WORKER_EXPR, "--", "--root", "/r",
                   "--output", "/o", "--threads", "2", "--in-place", "--files", "/r/a.blend",
                   "/r/b.blend", "--", "--method", "sphere"]
    assert "--threads" not in plan.task_command("b", ["/r/a.blend"], "/r", "/o", [])


def test_summary_rows_csv_and_exit_code(tmp_path):
    ok = dict(source="/r/a.blend", output="/o/a.blend", status="ok", attempts=2, seconds=1.5,
              bake=dict(method="sphere", seconds=1.25,
                        objects={"leaves": dict(vertices=100), "ground": dict(vertices=20)}))
    bad = plan.failed_report("/r/b.blend", "/o/b.blend", [], 2, "Blender exited with code 1\nx")
    rows = [plan.summary_row(ok, "/o/a.json"), plan.summary_row(bad, "/o/b.json")]
    assert rows[0]["method"] == "sphere" and rows[0]["objects"] == 2
    assert rows[0]["vertices"] == 120 and rows[0]["bake_seconds"] == "1.250"
    assert rows[1]["status"] == "failed" and rows[1]["error"] == "Blender exited with code 1 | x"
    path = str(tmp_path / "summary.csv")
    plan.write_summary(rows, path)
    with open(path, newline="") as f:
        back = list(csv.DictReader(f))
    assert [r["status"] for r in back] == ["ok", "failed"]
    assert tuple(back[0]) == plan.SUMMARY_FIELDS
    assert plan.exit_code(rows) == 1
    assert plan.exit_code(rows[:1] + [dict(rows[0], status="skipped")]) == 0


def test_report_writes_are_atomic_json(tmp_path):
    path = str(tmp_path / "deep" / "r.json")
    plan.write_report({"status": "ok", "x": 1.5}, path)
    with open(path) as f:
        assert json.load(f) == {"status": "ok", "x": 1.5}
    assert not os.path.exists(path + ".tmp")
    assert plan.read_report(str(tmp_path / "none.json")) is None


def test_the_batch_command_line_splits_at_the_first_double_dash():
    ours, bake = split_argv(["in/", "--output", "o", "--", "--method", "sphere", "--", "x"])
    assert bake == ["--method", "sphere", "--", "x"]
    a = build_parser().parse_args(ours)
    assert a.output == "o" and a.backend == "local" and a.jobs == 1
    with pytest.raises(SystemExit):
        build_parser().parse_args(["x", "--output", "o", "-j", "0"])
