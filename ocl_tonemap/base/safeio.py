"""Files that are never lost or left half-written, and reads of a user's path
that are always bounded.

Writes go to a temporary file beside the target (``.<name>.tmp<pid><ext>``),
are flushed to the disk (``fsync`` of the file), renamed over the target and the
folder is synced (so the rename itself survives a crash); any failure removes
the temporary file and raises :class:`WriteFailed` naming the file, with the
system's reason ("no space left on device"). Nothing counts as written before
that. Image writes are also read back (``imageio``) before the rename.

Reads of files named by the user (``--cuts``, ``--state-in``, a shot store's
JSON) accept regular files only, opened without blocking (a FIFO is refused,
never waited on), and at most a stated size (``/dev/zero`` is refused, not read).

For tests without a small file system: ``OCL_TONEMAP_FAIL_WRITE=N`` makes the
N-th commit of this process (1-based) fail as a full disk would (ENOSPC), after
its data was written to the temporary file. docs/reliability.md.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path

#: Largest text file read from a user's path (cuts lists, state JSON, a store's
#: JSON documents): 64 MiB (a state JSON is a few KiB; a shot's cut list a few).
TEXT_CAP = 64 << 20

_commits = 0


class WriteFailed(OSError):
    """A write that did not complete; nothing was put in place."""

    def __init__(self, path, why: str, err: int | None = None):
        super().__init__(err or errno.EIO, why)
        self.path, self.why = str(path), why

    def __str__(self) -> str:
        return f"cannot write {self.path}: {self.why}"


def reason(exc: BaseException) -> str:
    """An OSError in words ("no space left on device"), else its text."""
    if isinstance(exc, WriteFailed):
        return exc.why
    if isinstance(exc, OSError) and exc.errno is not None:
        return os.strerror(exc.errno).lower()
    return str(exc) or type(exc).__name__


#: A folder with less free space than this is full (a writer's failure there is a
#: full disk, whatever its library says).
FULL_BELOW = 1 << 16


def free_bytes(path) -> int | None:
    """Free bytes of the file system holding ``path``'s folder (None: unknown, as on a
    file system of no size: /proc, /sys report 0 blocks, not a full disk)."""
    try:
        st = os.statvfs(os.path.dirname(os.path.abspath(path)) or ".")
    except OSError:
        return None
    if st.f_blocks == 0:
        return None
    return st.f_bavail * st.f_frsize


#: Folders a file was made in (:func:`folder_refuses`' probe, once a process each).
_TOOK_A_FILE: set = set()


def folder_refuses(folder) -> str | None:
    """Why no file can be made in the existing ``folder`` ("a read-only file system",
    "permission denied" ...), or None where one can: its permissions (``os.access``),
    then, once a process for each folder, a real probe, an empty file made there
    (O_EXCL) and removed (root passes every permission check, and /proc takes no file
    while it reports no free space). A full disk is not refused here: its write says
    so."""
    d = os.path.abspath(folder)
    if not os.access(d, os.W_OK | os.X_OK):
        try:
            ro = bool(os.statvfs(d).f_flag & getattr(os, "ST_RDONLY", 1))
        except OSError:
            ro = False
        return "a read-only file system" if ro else "no write permission"
    if d in _TOOK_A_FILE:
        return None
    try:
        fd, probe = tempfile.mkstemp(prefix=".ocltm-probe-", dir=d)
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return None
        if exc.errno == errno.EROFS:
            return "a read-only file system"
        if exc.errno in (errno.EACCES, errno.EPERM):
            return "permission denied"
        if exc.errno == errno.ENOENT:     # (the folder is there: /proc's word for no)
            return "no file can be made in it"
        return f"no file can be made in it: {reason(exc)}"
    try:
        os.close(fd)
    finally:
        remove(probe)
    _TOOK_A_FILE.add(d)
    return None


def disk_full(path) -> bool:
    free = free_bytes(path)
    return free is not None and free < FULL_BELOW


def temp_path(path, ext: str | None = None) -> str:
    """The temporary name of ``path``'s write: beside it, hidden, with this process's
    id (``checkpoint.remove_stale_temps`` removes those of dead processes)."""
    p = Path(path)
    ext = p.suffix if ext is None else ext
    stem = p.name[:-len(p.suffix)] if p.suffix and ext == p.suffix else p.name
    return str(p.with_name(f".{stem}.tmp{os.getpid()}{ext}"))


_TEMP_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) \
    | getattr(os, "O_CLOEXEC", 0)


def open_temp(tmp, target=None) -> int:
    """The temporary file ``tmp`` made empty and opened for writing (a descriptor),
    never through what is in its place: no link is followed, and a link, a FIFO, a
    folder or a file with other names there is refused (:class:`WriteFailed` naming
    ``target`` and it; nothing is written through it). A regular file of that name
    (this pid's name, left by an earlier process that had it) is replaced."""
    for _ in range(3):
        try:
            return os.open(tmp, _TEMP_FLAGS, 0o644)
        except FileExistsError:
            pass
        except OSError as exc:
            raise WriteFailed(target or tmp, reason(exc), exc.errno) from None
        try:
            st = os.lstat(tmp)
        except FileNotFoundError:
            continue
        if stat.S_ISREG(st.st_mode) and st.st_nlink == 1:
            remove(tmp)
            continue
        kind = "a symbolic link" if stat.S_ISLNK(st.st_mode) else (
            file_kind(st.st_mode) or f"a file with {st.st_nlink} names (a hard link)")
        raise WriteFailed(target or tmp, f"{tmp} is {kind}, in the place of this tool's "
                          "temporary file; nothing was written through it (remove it)",
                          errno.EEXIST)
    raise WriteFailed(target or tmp, f"cannot make the temporary file {tmp}", errno.EEXIST)


def claim_temp(tmp, target=None) -> str:
    """``tmp`` made as an empty file of ours (:func:`open_temp`) before a library
    (OIIO, matplotlib) writes it by its name; returns it."""
    os.close(open_temp(tmp, target))
    return str(tmp)


def remove(path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def fsync_path(path, folder: bool = False) -> None:
    """Flush a file (or a folder's entries) to the disk."""
    fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if folder else 0))
    try:
        os.fsync(fd)
    except OSError as exc:
        if not folder or exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):
            raise                      # some file systems cannot sync a folder: not an error
    finally:
        os.close(fd)


def _injected_fault(path) -> None:
    global _commits
    n = os.environ.get("OCL_TONEMAP_FAIL_WRITE")
    if not n:
        return
    _commits += 1
    if str(_commits) == n.strip():
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))


def commit(tmp, path, sync: bool = True) -> None:
    """Put a completely written temporary file in place: fsync it, rename it over
    ``path``, fsync the folder. On failure the temporary file is removed and
    :class:`WriteFailed` raised; ``path`` is as it was."""
    try:
        _injected_fault(path)
        if sync:
            fsync_path(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        remove(tmp)
        raise WriteFailed(path, reason(exc), exc.errno) from None
    if sync:
        try:
            fsync_path(os.path.dirname(os.path.abspath(path)) or ".", folder=True)
        except OSError as exc:
            raise WriteFailed(path, f"written, but its folder could not be synced: "
                              f"{reason(exc)}", exc.errno) from None


def write_bytes(path, data: bytes, sync: bool = True) -> None:
    """``data`` to ``path``, whole or not at all."""
    tmp = temp_path(path, "")
    fd = open_temp(tmp, path)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
    except OSError as exc:
        remove(tmp)
        raise WriteFailed(path, reason(exc), exc.errno) from None
    except BaseException:
        remove(tmp)
        raise
    commit(tmp, path, sync)


def write_text(path, text: str, sync: bool = True) -> None:
    write_bytes(path, text.encode("utf-8"), sync)


def read_bytes(path, what: str, cap: int = TEXT_CAP) -> bytes:
    """A user's file, read whole: a regular file of at most ``cap`` bytes (a FIFO,
    a device or a folder is refused at once, never waited on). ``what`` names it in
    the error (``--cuts``)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise ValueError(f"{what} {path}: {reason(exc)}") from None
    _check_regular(st, path, what)
    if st.st_size > cap:
        raise ValueError(f"{what} {path} is {st.st_size} bytes, more than the {cap} "
                         "bytes such a file can be")
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise ValueError(f"{what} {path}: {reason(exc)}") from None
    try:
        with os.fdopen(fd, "rb") as f:
            data = f.read(cap + 1)
    except OSError as exc:
        raise ValueError(f"{what} {path}: {reason(exc)}") from None
    if len(data) > cap:                  # it grew while read
        raise ValueError(f"{what} {path} is more than the {cap} bytes such a file can be")
    return data


def read_text(path, what: str, cap: int = TEXT_CAP) -> str:
    data = read_bytes(path, what, cap)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{what} {path} is not text (UTF-8)") from None


class NotAFile(ValueError):
    """A user's path that is not a regular file (a FIFO, a socket, a device, a folder):
    ``<path>: is a named pipe (FIFO), not a file``. Refused before it is opened: a
    FIFO's open waits for a writer inside the library that opens it, where no signal
    can reach."""

    def __init__(self, path, kind: str):
        self.path, self.kind = str(path), kind
        super().__init__(f"{self.path}: is {kind}, not a file")

    @property
    def why(self) -> str:
        return f"is {self.kind}, not a file"


def file_kind(mode: int) -> str | None:
    """What a ``st_mode`` that is not a regular file is, in words (None: a regular file)."""
    if stat.S_ISREG(mode):
        return None
    return ("a named pipe (FIFO)" if stat.S_ISFIFO(mode) else "a folder" if stat.S_ISDIR(mode)
            else "a socket" if stat.S_ISSOCK(mode)
            else "a character device" if stat.S_ISCHR(mode)
            else "a block device" if stat.S_ISBLK(mode) else "not a regular file")


def _check_regular(st, path, what: str = "") -> None:
    kind = file_kind(st.st_mode)
    if kind is not None:
        raise NotAFile(path, kind)


def regular_file(path, what: str = "") -> None:
    """Refuse a path that is not a regular file, before anything opens it (a FIFO
    would hang its reader): :class:`NotAFile`; one that is not there, in words
    (``what`` names it: ``--state-in x: no such file or directory``)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise ValueError(f"{what + ' ' if what else ''}{path}: {reason(exc)}") from None
    _check_regular(st, path, what)


def check_input(path) -> None:
    """The one check of every file the tool opens for reading (images, masks, OCIO
    configs, state files, cut lists), made before it is opened: a regular file, else
    :class:`NotAFile` (``<path>: is a named pipe (FIFO), not a file``). A path that
    is not there (or cannot be looked at) is left to the caller's own words."""
    try:
        st = os.stat(path)
    except OSError:
        return
    _check_regular(st, path)
