"""A single-node Slurm cluster on loopback, for tests and benchmarks: munged, slurmctld and slurmd
started from Debian's packages with a slurm.conf generated in a temporary folder (state, spool,
logs, sockets and keys all in it; ports on 127.0.0.1 only; no cgroups), stopped on exit.

    with SlurmCluster() as cluster:
        subprocess.run(["sbatch", ...], env=cluster.env)

``missing()`` names the binaries that are not installed (the caller skips with that reason).
"""

import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time

BINARIES = ("munged", "slurmctld", "slurmd", "sbatch", "sinfo", "scontrol")


def missing():
    """The Slurm/munge programs not found on PATH (also looked for in /usr/sbin)."""
    return [b for b in BINARIES if _which(b) is None]


def _which(name):
    return shutil.which(name) or shutil.which(name, path="/usr/sbin:/sbin")


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _memory_mb():
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) // 1024
    return 1024


class SlurmCluster:
    """Context manager: a running one-node cluster; ``env`` points Slurm's commands at it."""

    def __init__(self, cpus=None, start_timeout=60.0):
        self.cpus = cpus or os.cpu_count() or 1
        self.start_timeout = start_timeout
        self.procs = []
        self.dir = None
        self.env = None

    # === Lifecycle
    def __enter__(self):
        self.dir = tempfile.mkdtemp(prefix="canopy_ao_slurm_")
        try:
            self._start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc):
        self.stop()
        return False

    def stop(self):
        """Stops every daemon this object started (TERM, then KILL), then removes its folder."""
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 10
        for proc in reversed(self.procs):
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.procs = []
        if self.dir:
            shutil.rmtree(self.dir, ignore_errors=True)
            self.dir = None

    # === Start-up
    def _path(self, *parts):
        return os.path.join(self.dir, *parts)

    def _start(self):
        for sub in ("state", "spool", "log", "munge"):
            os.makedirs(self._path(sub), mode=0o700)
        key = self._path("munge", "munge.key")
        with open(key, "wb") as f:
            f.write(os.urandom(1024))
        os.chmod(key, 0o400)
        socket_path = self._path("munge", "munge.socket")
        self._spawn([_which("munged"), "--foreground", "--force", f"--key-file={key}",
                     f"--socket={socket_path}", f"--pid-file={self._path('munge', 'munged.pid')}",
                     f"--seed-file={self._path('munge', 'munged.seed')}",
                     f"--log-file={self._path('log', 'munged.log')}"], "munged")
        self._wait(lambda: os.path.exists(socket_path), "munged's socket", "munged.log")

        conf = self._path("slurm.conf")
        with open(conf, "w") as f:
            f.write(self._conf(socket_path))
        self.env = dict(os.environ, SLURM_CONF=conf)
        self._spawn([_which("slurmctld"), "-D", "-i", "-f", conf], "slurmctld")
        self._wait(self._controller_up, "slurmctld to answer", "slurmctld.log")
        self._spawn([_which("slurmd"), "-D", "-f", conf, "-N", "localhost"], "slurmd")
        self._wait(self._node_idle, "the node to register as idle", "slurmd.log")

    def _conf(self, munge_socket):
        user = os.environ.get("USER") or __import__("pwd").getpwuid(os.getuid()).pw_name
        mem = max(256, _memory_mb() - 1024)
        return f"""\
ClusterName=canopyao
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
CommunicationParameters=NoInAddrAny
SlurmUser={user}
SlurmdUser={user}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={munge_socket}
StateSaveLocation={self._path('state')}
SlurmdSpoolDir={self._path('spool')}
SlurmctldPidFile={self._path('slurmctld.pid')}
SlurmdPidFile={self._path('slurmd.pid')}
SlurmctldLogFile={self._path('log', 'slurmctld.log')}
SlurmdLogFile={self._path('log', 'slurmd.log')}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
NodeName=localhost NodeAddr=127.0.0.1 CPUs={self.cpus} RealMemory={mem} State=UNKNOWN
PartitionName=batch Nodes=localhost Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
"""

    def _spawn(self, argv, name):
        log = open(self._path("log", f"{name}.stdout"), "wb")
        self.procs.append(subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT,
                                           env=self.env or os.environ, start_new_session=True))
        log.close()

    def _controller_up(self):
        return subprocess.run([_which("scontrol"), "ping"], env=self.env, capture_output=True,
                              text=True).stdout.find("UP") >= 0

    def _node_idle(self):
        out = subprocess.run([_which("sinfo"), "-h", "-N", "-o", "%t"], env=self.env,
                             capture_output=True, text=True).stdout.strip()
        return out.startswith("idle")

    def _wait(self, ready, what, log_name):
        deadline = time.monotonic() + self.start_timeout
        while time.monotonic() < deadline:
            for proc in self.procs:
                if proc.poll() is not None:
                    raise RuntimeError(f"a Slurm daemon exited ({proc.args[0]}, code "
                                       f"{proc.returncode}) while waiting for {what}:\n"
                                       + self.log_tail(log_name))
            if ready():
                return
            time.sleep(0.3)
        raise RuntimeError(f"timed out waiting for {what}:\n" + self.log_tail(log_name))

    def log_tail(self, name, lines=30):
        """The last lines of one of the daemons' logs (for failure messages)."""
        out = []
        for path in (self._path("log", name), self._path("log", name.replace(".log", ".stdout"))):
            if os.path.exists(path):
                with open(path, errors="replace") as f:
                    out.append(f"--- {os.path.basename(path)}\n" + "".join(f.readlines()[-lines:]))
        return "\n".join(out)
