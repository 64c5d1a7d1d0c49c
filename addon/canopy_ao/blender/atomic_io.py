"""Files replaced atomically (docs/DESIGN.md, 'Ownership of what a bake writes'). A write goes
to a temporary file beside its target (same folder, so the same file system), is flushed to
disk and renamed over the target (os.replace): a kill at any moment leaves the old file or the
new one, never neither. The old bytes a rollback needs are held in memory, never in a file of
their own, so a kill leaves no copy behind; the only thing a kill can leave is the temporary
file, which the next write of that path on this machine removes once its writer is gone."""

import os
import secrets
import socket
import stat

from ..core.fingerprint import name_digest

TEMP_TAG = ".canopy_ao-tmp"


def _temp_prefix(path):
    """'.<name>.canopy_ao-tmp.<host digest>.': what every temporary file of path on this
    machine starts with (a dot-name: hidden on Linux and macOS, read by nothing)."""
    d, base = os.path.split(path)
    return os.path.join(d, f".{base}{TEMP_TAG}.{name_digest(socket.gethostname())}.")


def temp_path(path):
    """A new temporary name beside path: the prefix, this process's id, a random token and
    path's extension (OpenImageIO picks the format by it)."""
    ext = os.path.splitext(path)[1]
    return f"{_temp_prefix(path)}{os.getpid()}.{secrets.token_hex(4)}{ext}"


def _running(pid):
    """Whether process pid runs on this machine. On Windows, where os.kill would end it,
    always True: a temporary file there stays until removed by hand (nothing reads it)."""
    if os.name == "nt":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process
        return True
    return True


def clean_stale(path):
    """Remove the temporary files of path that writes killed on this machine left: those of a
    process no longer running, or of this process (its writes run one at a time, so a
    temporary file of its own is a leftover). Another machine's (a shared folder) stay."""
    prefix = _temp_prefix(path)
    d, start = os.path.split(prefix)
    try:
        names = os.listdir(d)
    except OSError:
        return
    for f in names:
        pid = f[len(start):].split(".")[0] if f.startswith(start) else ""
        if pid.isdigit() and (int(pid) == os.getpid() or not _running(int(pid))):
            try:
                os.remove(os.path.join(d, f))
            except OSError:
                pass


def _fsync(path, directory=False):
    """Flush path's data (or, directory=True, a folder's entries: the rename) to disk; a file
    system that cannot (a folder on Windows) is left to its own flush."""
    try:
        fd = os.open(path, os.O_RDONLY if directory else os.O_RDWR | getattr(os, "O_BINARY", 0))
    except OSError:
        if directory:
            return
        raise
    try:
        os.fsync(fd)
    except OSError:
        if not directory:
            raise
    finally:
        os.close(fd)


def replace_file(path, write):
    """Make path hold what write(tmp) writes to the file tmp, atomically: write beside to a
    temporary name, flush it, give it the replaced file's permissions, os.replace it over path,
    flush the folder. A failure (or an exception in write) removes the temporary file and
    leaves path as it was."""
    clean_stale(path)
    tmp = temp_path(path)
    try:
        write(tmp)
        _fsync(tmp)
        try:
            os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))
        except FileNotFoundError:
            pass
        os.replace(tmp, path)
    except BaseException:
        try:
            os.remove(tmp)
        except OSError:
            pass
        raise
    _fsync(os.path.dirname(path) or ".", directory=True)


def _write_bytes(data):
    def write(tmp):
        with open(tmp, "wb") as f:
            f.write(data)
    return write


def keep_file(path):
    """undo() that puts back the file at path as it is now (its bytes are read into memory
    here), atomically, or removes what was written there when there was no file."""
    old = None
    if os.path.isfile(path):
        with open(path, "rb") as f:
            old = f.read()

    def undo():
        if old is not None:
            replace_file(path, _write_bytes(old))
        elif os.path.isfile(path):
            os.remove(path)
    return undo


def remove_file(path, txn):
    """Remove the file at path, its bytes kept in txn (commit.Transaction) for a rollback."""
    txn.add(keep_file(path))
    os.remove(path)
