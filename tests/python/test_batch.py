"""Batch bakes end to end: `python3 -m canopy_ao.batch` on tiny generated scenes, through the
local back end, GNU parallel and a real single-node Slurm cluster (started here, on loopback),
and the Flamenco job type's command lines against the batch's own.

These start Blender processes (the batch's tasks), so they need Blender and the built module
as the Blender tests do. The Slurm test skips only when Slurm's programs are not installed
(scripts/install_deps.sh installs them).
"""

import csv
import hashlib
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import pytest

import slurm_cluster

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ADDON_PARENT = os.path.join(REPO, "addon")
JOB_TYPE = os.path.join(REPO, "scripts", "flamenco", "canopy_ao_batch.js")
HARNESS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "flamenco_harness.js")
BAKE = ["--method", "sphere", "--tau", "1.5"]  # fast, and no calibration: tiny scenes
BLENDER = shutil.which("blender")

pytestmark = pytest.mark.skipif(BLENDER is None, reason="Blender is not installed "
                                "(scripts/install_deps.sh installs it)")


@pytest.fixture(scope="module")
def env():
    """The environment of the batch command: the add-on found through a throw-away
    BLENDER_USER_SCRIPTS folder (as scripts/test.sh does) and importable by python3."""
    d = tempfile.mkdtemp(prefix="canopy_ao_batch_scripts_")
    os.makedirs(os.path.join(d, "addons"))
    os.symlink(os.path.join(ADDON_PARENT, "canopy_ao"), os.path.join(d, "addons", "canopy_ao"))
    yield dict(os.environ, BLENDER_USER_SCRIPTS=d, PYTHONPATH=ADDON_PARENT)
    shutil.rmtree(d, ignore_errors=True)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Four tiny round trees (seeds 0-3, 300 leaves, ~5.7k vertices with trunk and ground)."""
    d = str(tmp_path_factory.mktemp("scenes"))
    subprocess.run([BLENDER, "-b", "--factory-startup", "--python",
                    os.path.join(REPO, "examples", "make_batch_scenes.py"), "--", "--out", d,
                    "--count", "4", "--leaves", "300"], check=True, capture_output=True)
    return sorted(os.path.join(d, f) for f in os.listdir(d))


def _inputs(scenes, folder, n):
    os.makedirs(folder)
    return [shutil.copy2(s, folder) for s in scenes[:n]]


def batch(env, *args, bake=BAKE):
    out = subprocess.run([sys.executable, "-m", "canopy_ao.batch", *args, "--", *bake],
                         env=env, capture_output=True, text=True, timeout=600)
    return out.returncode, out.stdout + out.stderr


def summary(out_dir):
    with open(os.path.join(out_dir, "summary.csv"), newline="") as f:
        return {os.path.basename(r["source"]): r for r in csv.DictReader(f)}


def _digest(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def check_outputs(env, pairs):
    """Opens each (source, output) pair in one Blender: the output's meshes carry the AO
    attribute with values in [0, 1] and the mean the report states; the source has none."""
    script = r"""
import bpy, json, sys
import numpy as np
res = {}
for src, out in json.loads(sys.argv[sys.argv.index("--") + 1]):
    row = {}
    for which, path in (("source", src), ("output", out)):
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
        for ob in bpy.data.objects:
            if ob.type != 'MESH':
                continue
            a = ob.data.color_attributes.get("CanopyAO")
            if a is None:
                row[f"{which}:{ob.name}"] = None
                continue
            v = np.empty(len(a.data) * 4, np.float32)
            a.data.foreach_get("color", v)
            ao = v[0::4]
            row[f"{which}:{ob.name}"] = [float(ao.min()), float(ao.max()), float(ao.mean())]
    res[out] = row
print("RESULT" + json.dumps(res))
"""
    r = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-expr", script, "--",
                        json.dumps(pairs)], env=env, capture_output=True, text=True,
                       timeout=300)
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT")]
    assert line, r.stdout + r.stderr
    found = json.loads(line[0][len("RESULT"):])
    for src, out in pairs:
        with open(out[:-len(".blend")] + ".canopy_ao.json") as f:
            rep = json.load(f)
        row = found[out]
        baked = {k.split(":", 1)[1]: v for k, v in row.items() if k.startswith("output:")}
        assert set(baked) == set(rep["bake"]["objects"]), (out, row)
        for name, (lo, hi, mean) in baked.items():
            assert 0.0 <= lo <= hi <= 1.0 and lo < hi, (out, name, lo, hi)
            assert mean == pytest.approx(rep["bake"]["objects"][name]["ao_mean"], abs=1e-4)
        assert all(v is None for k, v in row.items() if k.startswith("source:")), row


def test_local_batch_outputs_summary_retry_failure_resume(tmp_path, env, scenes):
    srcs = _inputs(scenes, str(tmp_path / "in"), 3)
    corrupt = str(tmp_path / "in" / "zz_corrupt.blend")
    with open(corrupt, "wb") as f:
        f.write(b"not a blend file" * 64)
    before = {s: (_digest(s), os.stat(s).st_mtime_ns) for s in srcs}
    # A Blender that dies (SIGKILL, no report) the first time it is given the third scene:
    # its whole task fails once, and each of its files must then succeed on its own retry.
    marker = str(tmp_path / "crashed-once")
    fake = str(tmp_path / "blender")
    with open(fake, "w") as f:
        f.write(f"#!/bin/sh\ncase \"$*\" in *{os.path.basename(srcs[2])}*)\n"
                f"  [ -e {marker} ] || {{ touch {marker}; kill -KILL $$; }};;\nesac\n"
                f"exec {shlex.quote(BLENDER)} \"$@\"\n")
    os.chmod(fake, 0o755)
    out = str(tmp_path / "out")
    args = [str(tmp_path / "in"), "--output", out, "-j", "2", "--files-per-task", "2",
            "--threads", "1", "--blender", fake]

    code, log = batch(env, *args)
    assert code == 1, log  # one file failed twice
    rows = summary(out)
    names = [os.path.basename(s) for s in srcs]
    assert sorted(rows) == sorted(names + ["zz_corrupt.blend"])
    # Tasks: [scene 0, scene 1] and [scene 2, corrupt]; the second crashed once.
    assert [(rows[n]["status"], rows[n]["attempts"]) for n in names] == \
        [("ok", "1"), ("ok", "1"), ("ok", "2")], log
    bad = rows["zz_corrupt.blend"]
    assert (bad["status"], bad["attempts"]) == ("failed", "2")
    assert "File format is not supported" in bad["error"], bad
    assert not os.path.exists(os.path.join(out, "zz_corrupt.blend"))
    assert "FAILED" in log and "zz_corrupt.blend" in log
    for n in names:
        assert rows[n]["method"] == "sphere" and int(rows[n]["objects"]) == 3
        assert int(rows[n]["vertices"]) > 1000
    assert {s: (_digest(s), os.stat(s).st_mtime_ns) for s in srcs} == before  # untouched
    outputs = [os.path.join(out, n) for n in names]
    check_outputs(env, list(zip(srcs, outputs)))

    # Resume: nothing is re-baked; the corrupt file is tried (and fails) again.
    stamps = {o: os.stat(o).st_mtime_ns for o in outputs}
    code, log = batch(env, *args)
    assert code == 1, log
    rows = summary(out)
    assert [rows[n]["status"] for n in names] == ["skipped"] * 3
    assert {o: os.stat(o).st_mtime_ns for o in outputs} == stamps

    # An edited source is re-baked, the others stay; without a failure the exit code is 0.
    os.remove(corrupt)
    os.utime(srcs[0])
    code, log = batch(env, *args)
    assert code == 0, log
    rows = summary(out)
    assert [rows[n]["status"] for n in names] == ["ok", "skipped", "skipped"], log
    assert os.stat(outputs[0]).st_mtime_ns > stamps[outputs[0]]
    assert os.stat(outputs[1]).st_mtime_ns == stamps[outputs[1]]

    # Other bake options invalidate every result.
    code, log = batch(env, *args, "--dry-run", bake=["--method", "ellipsoid"])
    assert code == 0 and "0 up to date, 3 to bake in 2 task(s)" in log, log


def test_bad_batch_arguments_exit_2_before_any_bake(tmp_path, env, scenes):
    srcs = _inputs(scenes, str(tmp_path / "in"), 1)
    code, log = batch(env, str(tmp_path / "nothing*.blend"), "--output", str(tmp_path / "o"))
    assert code == 2 and "no .blend file matches" in log
    code, log = batch(env, srcs[0], "--output", str(tmp_path / "o"), bake=["--save"])
    assert code == 2 and "--save is set by the batch" in log
    code, log = batch(env, srcs[0], "--output", str(tmp_path / "in"))
    assert code == 2 and "would overwrite it" in log
    assert not os.path.exists(tmp_path / "o")


@pytest.mark.parametrize("args, bake, message", [
    (["--timeout", "nan"], BAKE, "--timeout: must be a finite number of seconds >= 0"),
    (["--timeout", "-1"], BAKE, "--timeout: must be a finite number of seconds >= 0"),
    (["--poll", "inf"], BAKE, "--poll: must be a finite number of seconds >= 0"),
    # bake options each file's bake would refuse: refused here, before any Blender starts
    ([], ["--tau", "1e300"], "tau must be a finite number in (0, 10000]"),
    ([], ["--distance", "1e-30"], "distance must be a finite number 0 or in [1e-09, 1e+10]"),
    ([], ["--method", "bogus"], "method must be one of"),
    (["--threads", "100000"], BAKE, "--threads must be an integer in [0, 65536]"),
])
def test_bad_numbers_and_bake_options_exit_2_before_any_blender(tmp_path, args, bake, message):
    marker = tmp_path / "blender_started"
    fake = tmp_path / "blender.sh"  # a Blender that only says it was started
    fake.write_text(f"#!/bin/sh\ntouch {shlex.quote(str(marker))}\n")
    fake.chmod(0o755)
    src = tmp_path / "in" / "a.blend"
    src.parent.mkdir()
    src.write_bytes(b"BLENDER")
    env = dict(os.environ, PYTHONPATH=ADDON_PARENT)
    code, log = batch(env, str(src), "--output", str(tmp_path / "o"), "--blender", str(fake),
                      *args, bake=bake)
    assert code == 2 and message in log and "Traceback" not in log, log
    assert not marker.exists() and not os.path.exists(tmp_path / "o")


# tgkill(2), to hand a signal to one thread of another process as the kernel may hand Ctrl-C's.
_TGKILL = {"x86_64": 234, "aarch64": 131}.get(os.uname().machine)


def _signal_a_worker_thread(pid):
    """SIGINT to a thread of process pid other than its main one (a worker of the pool)."""
    import ctypes
    tids = [int(t) for t in os.listdir(f"/proc/{pid}/task") if int(t) != pid]
    assert tids, "the batch has no worker thread"
    libc = ctypes.CDLL(None, use_errno=True)
    assert libc.syscall(_TGKILL, pid, tids[0], int(signal.SIGINT)) == 0, ctypes.get_errno()


@pytest.mark.parametrize("to", ["process", pytest.param("worker thread", marks=pytest.mark.skipif(
    _TGKILL is None or not os.path.isdir("/proc/self/task"), reason="needs Linux tgkill"))])
def test_ctrl_c_stops_every_blender_and_starts_no_retry(tmp_path, env, to):
    """A cancelled batch leaves no Blender running (they run in their own sessions, out of a
    terminal's reach) and exits 130, also when the kernel hands the SIGINT to a worker thread
    (then it interrupts no wait of the main thread's: the run must look for it)."""
    for i in range(3):
        (tmp_path / "in").mkdir(exist_ok=True)
        (tmp_path / "in" / f"s{i}.blend").write_bytes(b"stand-in")
    pids = tmp_path / "pids"
    fake = tmp_path / "blender"
    fake.write_text(f"#!/bin/sh\necho $$ >> {pids}\nexec sleep 120\n")
    fake.chmod(0o755)
    proc = subprocess.Popen([sys.executable, "-m", "canopy_ao.batch", str(tmp_path / "in"),
                             "--output", str(tmp_path / "out"), "-j", "2", "--blender",
                             str(fake), "--", *BAKE], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        for _ in range(300):  # both slots busy
            if pids.exists() and len(pids.read_text().split()) == 2:
                break
            time.sleep(0.1)
        started = [int(x) for x in pids.read_text().split()]
        assert len(started) == 2
        if to == "process":
            proc.send_signal(signal.SIGINT)
        else:
            _signal_a_worker_thread(proc.pid)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
        survivors = []
        for pid in (int(x) for x in pids.read_text().split()) if pids.exists() else ():
            try:
                os.kill(pid, signal.SIGKILL)  # the test never leaves one behind
                survivors.append(pid)
            except ProcessLookupError:
                pass
    assert not survivors, f"Blender processes outlived the cancelled batch: {survivors}"
    assert proc.returncode == 130 and "cancelled" in out, out
    assert [int(x) for x in pids.read_text().split()] == started  # nothing started after


@pytest.mark.skipif(shutil.which("parallel") is None, reason="GNU parallel is not installed "
                    "(scripts/install_deps.sh installs it)")
def test_gnu_parallel_back_end_runs_the_same_tasks(tmp_path, env, scenes):
    srcs = _inputs(scenes, str(tmp_path / "in"), 3)
    out = str(tmp_path / "out")
    code, log = batch(env, str(tmp_path / "in"), "--output", out, "--backend", "parallel",
                      "-j", "2", "--files-per-task", "2")
    assert code == 0 and "3 to bake in 2 task(s) on parallel" in log, log
    rows = summary(out)
    assert [rows[os.path.basename(s)]["status"] for s in srcs] == ["ok"] * 3, log
    check_outputs(env, [(s, os.path.join(out, os.path.basename(s))) for s in srcs])


@pytest.mark.skipif(bool(slurm_cluster.missing()), reason="Slurm is not installed (missing "
                    + ", ".join(slurm_cluster.missing()) + "; scripts/install_deps.sh installs "
                    "slurmctld, slurmd, slurm-client and munge)")
def test_slurm_array_batch_on_a_one_node_cluster(tmp_path, env, scenes):
    srcs = _inputs(scenes, str(tmp_path / "in"), 4)
    out = str(tmp_path / "out")
    args = [str(tmp_path / "in"), "--output", out, "--backend", "slurm", "-j", "2",
            "--files-per-task", "2", "--poll", "0.5"]
    with slurm_cluster.SlurmCluster() as cluster:
        slurm_env = dict(env, **{k: v for k, v in cluster.env.items() if k == "SLURM_CONF"})
        code, log = batch(slurm_env, *args)
        assert code == 0, log + cluster.log_tail("slurmctld.log") + cluster.log_tail("slurmd.log")
        # One array job: 4 files in 2 tasks, at most 2 running.
        assert "--array=0-1%2" in log and "4 to bake in 2 task(s) on slurm" in log, log
        rows = summary(out)
        assert [(rows[os.path.basename(s)]["status"], rows[os.path.basename(s)]["attempts"])
                for s in srcs] == [("ok", "1")] * 4, log
        logs = os.listdir(os.path.join(out, ".canopy_ao_batch", "logs"))
        assert sum(name.startswith("slurm-") for name in logs) == 2, logs
        code, log = batch(slurm_env, *args)  # resume: nothing is submitted
        assert code == 0 and "4 up to date, 0 to bake" in log and "submitted" not in log, log
    check_outputs(env, [(s, os.path.join(out, os.path.basename(s))) for s in srcs])


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed "
                    "(scripts/install_deps.sh installs nodejs)")
def test_flamenco_job_type_is_valid_and_authors_the_batch_command_lines(tmp_path, env, scenes):
    r = subprocess.run(["node", "--check", JOB_TYPE], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    srcs = _inputs(scenes, str(tmp_path / "in" / "a"), 2)
    srcs += _inputs(scenes[2:], str(tmp_path / "in" / "b"), 1)
    out = str(tmp_path / "out")
    bake_text = "--objects round_leaves 'round trunk' ground --method sphere --tau 1.5"
    bake = shlex.split(bake_text)
    for threads, per_task, in_place in ((1, 2, False), (0, 1, True)):
        extra = ["--in-place"] if in_place else []
        code, log = batch(env, *srcs, "--output", out, "--threads", str(threads),
                          "--files-per-task", str(per_task), "--dry-run", *extra, bake=bake)
        assert code == 0, log
        ours = [shlex.split(ln) for ln in log.splitlines() if ln.startswith(BLENDER + " ")
                or ln.startswith("blender ")]
        settings = dict(files="\n".join(srcs) + "\n", output=out, bake_args=bake_text,
                        threads=threads, files_per_task=per_task, in_place=in_place)
        with open(tmp_path / "settings.json", "w") as f:
            json.dump(settings, f)
        r = subprocess.run(["node", HARNESS, JOB_TYPE, str(tmp_path / "settings.json"),
                            "blender"], capture_output=True, text=True, check=True)
        job = json.loads(r.stdout)
        theirs = [c["argv"] for t in job["tasks"] for c in t["commands"]]
        assert all(t["type"] == "blender" and len(t["commands"]) == 1 for t in job["tasks"])
        assert len(ours) == -(-len(srcs) // per_task)
        assert theirs == ours


def _no_addon_env(env, tmp_path):
    """env of a farm worker whose Blender lacks the add-on: a BLENDER_USER_SCRIPTS without it
    and no PYTHONPATH (Blender's Python would find the package there)."""
    empty = tmp_path / "no_addon_scripts"
    (empty / "addons").mkdir(parents=True)
    bare = dict(env, BLENDER_USER_SCRIPTS=str(empty))
    bare.pop("PYTHONPATH", None)
    return bare


def _fails_loudly(argv, env, what, timeout=300):
    r = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=timeout)
    out = r.stdout + r.stderr
    assert r.returncode != 0, f"{what}: exit 0 without the add-on:\n{out[-2000:]}"
    return out


def test_every_generated_task_command_fails_without_the_addon(tmp_path, env, scenes):
    """The command lines the batch generates (its own tasks, the runner GNU parallel and each
    Slurm array element run, Flamenco's job type) exit non-zero on a worker whose Blender
    lacks the add-on, and no output is left that looks like a result."""
    from canopy_ao.batch import runner
    srcs = _inputs(scenes, str(tmp_path / "in"), 1)
    out = str(tmp_path / "out")
    bare = _no_addon_env(env, tmp_path)
    code, log = batch(env, *srcs, "--output", out, "--dry-run")
    (task,) = [shlex.split(ln) for ln in log.splitlines() if ln.startswith(BLENDER + " ")
               or ln.startswith("blender ")]
    text = _fails_loudly(task, bare, "the batch's task command")
    assert "No module named 'canopy_ao'" in text, text[-2000:]
    # The runner (GNU parallel's and Slurm's command) on the saved plan: python3 finds the
    # package by its own sys.path, the Blender it starts does not.
    p = runner.make_plan(srcs, os.path.dirname(srcs[0]), out, BAKE, [srcs], blender=BLENDER)
    plan_path = runner.save_plan(p)
    code = ("import sys; sys.path.insert(0, sys.argv[1]); from canopy_ao.batch import runner; "
            "sys.exit(runner.main(sys.argv[2:]))")
    _fails_loudly([sys.executable, "-c", code, ADDON_PARENT, plan_path, "0"], bare,
                  "the runner of GNU parallel and Slurm")
    assert not os.path.exists(os.path.join(out, os.path.basename(srcs[0])))
    if shutil.which("node") is None:
        pytest.skip("node is not installed (scripts/install_deps.sh installs nodejs)")
    with open(tmp_path / "settings.json", "w") as f:
        json.dump(dict(files=srcs[0] + "\n", output=out, bake_args=" ".join(BAKE), threads=0,
                       files_per_task=1, in_place=False), f)
    r = subprocess.run(["node", HARNESS, JOB_TYPE, str(tmp_path / "settings.json"), BLENDER],
                       capture_output=True, text=True, check=True)
    (flamenco,) = [c["argv"] for t in json.loads(r.stdout)["tasks"] for c in t["commands"]]
    text = _fails_loudly(flamenco, bare, "the Flamenco task")
    assert "No module named 'canopy_ao'" in text, text[-2000:]
