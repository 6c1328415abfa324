"""The locks of every writer of an output: a run's output frames and its state file,
a shot's apply chunks (``apply``, ``apply --chunk``, a Dask run's tasks, a farm's
jobs), an OCIO view export's folder.

A lock is a small file beside what it guards (``out/o.####.png`` ->
``out/.o.png.frames.lock``), holding a JSON record of who writes. Linux's
open-file-description record locks (``F_OFD_SETLK``; POSIX ``F_SETLK`` elsewhere)
on two bytes of it, far past its text, say who is alive:

- the *writer* byte: a run that writes alone (``run``, ``export`` of a serial run)
  holds it exclusively; the chunks of one shot hold it shared;
- the *record* byte: held exclusively for the few system calls that read or change
  the record (a mutex; every holder's wait on it is bounded by another's few calls).

So the chunks of one shot (one store, the same settings: the record says which) go
ahead together when their frames are disjoint, and any other writer is refused in
one line naming the output, the other writer's pid and what it writes. A lock left
by a killed process is free (the system released its locks): its record is stale and
rewritten. The kernel's conversion of a record lock is atomic, unlike ``flock``'s.

The lock file is made and opened without following a link, and must be a regular
file with one name, ours (owner) and either empty or a record of this tool's: a
link, a FIFO, a folder, a device, a hard link or a file of other data in its place
is refused in one line naming it, and nothing is written through it.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import stat
import struct
import uuid

from ..io.imageio import FrameError
from ..io.patterns import is_sequence, without_frame_token
from ..base.safeio import file_kind

#: The record lock commands: per open file description where the system has them
#: (Linux), so two Dask tasks in one worker process are two holders.
_SET = getattr(fcntl, "F_OFD_SETLK", fcntl.F_SETLK)
_SETW = getattr(fcntl, "F_OFD_SETLKW", fcntl.F_SETLKW)
_GET = getattr(fcntl, "F_OFD_GETLK", fcntl.F_GETLK)
#: ``struct flock`` (l_type, l_whence, l_start, l_len, l_pid) with its padding.
_FLOCK = "@hhqqi4x"
#: The writer and record bytes: far past any record's text.
WRITER_BYTE = 1 << 40
RECORD_BYTE = WRITER_BYTE + 1
#: The largest record read (a shot on a farm: one line per live chunk).
RECORD_CAP = 1 << 20
#: What a record says it is.
MAGIC = "ocl-tonemap lock"


class Locked(FrameError):
    """Another writer holds the lock (``FrameError``: one line naming the output)."""


def _flock(kind: int, start: int) -> bytes:
    return struct.pack(_FLOCK, kind, os.SEEK_SET, start, 1, 0)


def _try(fd: int, kind: int, start: int) -> bool:
    """Take (or convert to) ``kind`` on one byte without waiting; False: another holds it."""
    try:
        fcntl.fcntl(fd, _SET, _flock(kind, start))
        return True
    except OSError as exc:
        if exc.errno in (errno.EACCES, errno.EAGAIN):
            return False
        raise


def _wait(fd: int, kind: int, start: int) -> None:
    fcntl.fcntl(fd, _SETW, _flock(kind, start))


def _others_hold(fd: int, start: int) -> bool:
    """Whether another open file description holds any lock on the byte."""
    got = fcntl.fcntl(fd, _GET, _flock(fcntl.F_WRLCK, start))
    return struct.unpack(_FLOCK, got)[0] != fcntl.F_UNLCK


def settings_key(settings) -> str:
    """A short digest of a shot's settings (the serial run's fingerprint)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def lock_path(output: str, kind: str = "frames") -> str:
    """``out/o.####.png`` -> ``out/.o.png.frames.lock``; a folder or file ``x`` ->
    ``.x.<kind>.lock`` beside it."""
    d, name = os.path.split(os.path.abspath(output.rstrip(os.sep) or output))
    key = (without_frame_token(name) if is_sequence(name) else name) or "frames"
    return os.path.join(d, f".{key}.{kind}.lock")


def _alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ProcessLookupError, OverflowError, ValueError, TypeError):
        return False
    except PermissionError:
        return True
    return True


def folders_to_make(path: str) -> list:
    """The folders above ``path`` that do not exist yet, deepest first."""
    out = []
    d = os.path.dirname(os.path.abspath(path))
    while d and not os.path.isdir(d) and d != os.path.dirname(d):
        out.append(d)
        d = os.path.dirname(d)
    return out


def _frames(chunk) -> str:
    return "all frames" if chunk is None else f"frames {chunk[0]}-{chunk[1]}"


class OutputLock:
    """The lock on what one writer writes (``guarded``: an output pattern, a state
    file or an export folder, named in the errors). ``shot``: None, the writer is
    alone (a serial run); else ``(store, settings)``, and ``chunk`` its frames
    ``(a, b)`` (None: a shot's coordinator, which claims no frame: a Dask run's
    client). ``command`` names the writer to a refused one (``run``, ``apply``).
    ``why``: what a refused alone-writer is told to do."""

    def __init__(self, path: str, guarded: str, command: str = "run", shot=None, chunk=None,
                 why: str = "wait for it, or give another OUTPUT", within: str | None = None):
        self.path, self.guarded, self.command = path, guarded, command
        self.shot = None if shot is None else (os.path.abspath(str(shot[0])),
                                               settings_key(shot[1]))
        self.chunk = None if chunk is None else (int(chunk[0]), int(chunk[1]))
        self.why = why
        #: the token of the holder whose frames this one's are part of (a Dask run's)
        self.within = within
        self.token = uuid.uuid4().hex[:12]
        self.fd: int | None = None

    # -- the file ----------------------------------------------------------------------
    def _refuse(self, what: str) -> FrameError:
        return FrameError(self.path, None, f"{what}, in the place of the lock of "
                          f"{self.guarded}; nothing was written through it (remove it, "
                          "or give another OUTPUT)")

    def _open(self) -> int:
        """The lock file's descriptor: made here (no link followed), or the one there if
        it is a lock file of ours."""
        flags = os.O_RDWR | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) \
            | getattr(os, "O_CLOEXEC", 0)
        try:
            return os.open(self.path, flags | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            pass
        except OSError as exc:
            raise self._error(exc) from None
        try:
            fd = os.open(self.path, flags)
        except FileNotFoundError:
            return -1                                  # removed meanwhile: again
        except OSError as exc:
            raise self._error(exc) from None
        try:
            st = os.fstat(fd)
            if st.st_nlink == 0:                       # unlinked as it was opened: again
                os.close(fd)
                return -1
            kind = file_kind(st.st_mode)
            if kind is not None:
                raise self._refuse(f"is {kind}")
            if st.st_nlink != 1:
                raise self._refuse(f"is a file with {st.st_nlink} names (a hard link), "
                                   "not a lock file of this tool's")
            if hasattr(os, "getuid") and st.st_uid != os.getuid():
                raise self._refuse(f"belongs to another user (uid {st.st_uid})")
        except BaseException:
            os.close(fd)
            raise
        return fd

    def _error(self, exc: OSError) -> FrameError:
        if exc.errno == errno.ELOOP:
            return self._refuse("is a symbolic link")
        if exc.errno == errno.EISDIR:
            return self._refuse("is a folder")
        if exc.errno == errno.ENXIO:
            return self._refuse("is a socket")
        return FrameError(self.path, None, f"cannot make the lock of {self.guarded}: "
                          f"{os.strerror(exc.errno).lower() if exc.errno else exc}")

    def _read(self, fd: int) -> dict | None:
        """The record (None: empty, or a stale lock of an earlier version: a pid)."""
        size = os.fstat(fd).st_size
        if size > RECORD_CAP:
            raise self._refuse(f"is a file of {size} bytes, not a lock file of this tool's")
        text = os.pread(fd, RECORD_CAP, 0).decode("utf-8", "replace").strip()
        if not text or text.isdigit():
            return None
        try:
            rec = json.loads(text)
        except ValueError:
            rec = None
        if not isinstance(rec, dict) or rec.get("what") != MAGIC \
                or not isinstance(rec.get("holders"), list):
            raise self._refuse("is a file of other data, not a lock file of this tool's")
        return rec

    def _write(self, fd: int, rec: dict) -> None:
        data = (json.dumps(rec, sort_keys=True) + "\n").encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, data, 0)

    def _same_file(self, fd: int) -> bool:
        try:
            return os.fstat(fd).st_ino == os.lstat(self.path).st_ino
        except FileNotFoundError:
            return False

    # -- taking and leaving -------------------------------------------------------------
    def _me(self) -> dict:
        return {"pid": os.getpid(), "token": self.token, "command": self.command,
                "chunk": None if self.chunk is None else list(self.chunk)}

    def acquire(self) -> "OutputLock":
        made = folders_to_make(self.path)
        try:
            os.makedirs(os.path.dirname(self.path), exist_ok=True)
        except OSError as exc:
            raise self._error(exc) from None
        try:
            return self._acquire()
        except BaseException:
            for d in made:                   # (deepest first) a refused writer leaves none
                try:
                    os.rmdir(d)
                except OSError:
                    pass
            raise

    def _acquire(self) -> "OutputLock":
        for _ in range(20):
            fd = self._open()
            if fd < 0:
                continue
            try:
                _wait(fd, fcntl.F_WRLCK, RECORD_BYTE)
                if not self._same_file(fd):            # removed by a writer that left
                    os.close(fd)
                    continue
                self._take(fd)
            except BaseException:
                os.close(fd)
                raise
            self.fd = fd
            _HELD.add(self)
            return self
        raise FrameError(self.path, None, f"cannot take the lock of {self.guarded}")

    def _take(self, fd: int) -> None:
        """Holding the record byte: the writer byte taken, the record checked and
        written; then the record byte let go (on a refusal, the caller closes the
        descriptor, and every lock of it goes)."""
        alone = self.shot is None
        got = _try(fd, fcntl.F_WRLCK if alone else fcntl.F_RDLCK, WRITER_BYTE)
        rec = self._read(fd)
        live = [h for h in (rec or {}).get("holders", []) if isinstance(h, dict)
                and _alive(h.get("pid"))]
        if not got:
            raise Locked(self.guarded, None, self._held_by(rec, live))
        if not alone and rec is not None and _others_hold(fd, WRITER_BYTE):
            why = self._conflict(rec, live)
            if why is not None:
                raise Locked(self.guarded, None, why)
            rec["holders"] = live + [self._me()]
        else:                                   # alone, or the first of a shot's writers
            rec = {"what": MAGIC, "guards": os.path.abspath(self.guarded),
                   "shot": None if alone else {"store": self.shot[0],
                                               "settings": self.shot[1]},
                   "holders": [self._me()]}
        self._write(fd, rec)
        _try(fd, fcntl.F_UNLCK, RECORD_BYTE)

    def _what(self) -> str:
        return "these output frames" if is_sequence(self.guarded) else "this output"

    def _held_by(self, rec: dict | None, live: list) -> str:
        """Why a writer that could not take the writer byte is refused."""
        who = live[0] if live else {}
        pid = f" (pid {who['pid']})" if who.get("pid") else ""
        shot = (rec or {}).get("shot")
        if shot is not None:
            return (f"an ocl-tonemap {who.get('command', 'apply')}{pid} of the shot store "
                    f"{shot.get('store')} is writing {self._what()}; wait for it, or give "
                    "another OUTPUT")
        return f"another ocl-tonemap {who.get('command', 'run')}{pid} is writing " \
            f"{self._what()}; {self.why}"

    def _conflict(self, rec: dict, live: list) -> str | None:
        """Why a shot's writer may not join the holders of a shot's lock (None: it may)."""
        shot = rec.get("shot") or {}
        who = live[0] if live else {}
        pid = f" (pid {who['pid']})" if who.get("pid") else ""
        cmd = who.get("command", "apply")
        if shot.get("store") != self.shot[0]:
            return (f"an ocl-tonemap {cmd}{pid} of another shot store "
                    f"({shot.get('store')}) is writing {self._what()}; wait for it, or "
                    "give another OUTPUT")
        if shot.get("settings") != self.shot[1]:
            return (f"an ocl-tonemap {cmd}{pid} of this shot store with other settings is "
                    f"writing {self._what()}; wait for it, or give the same settings")
        for h in live:
            c = h.get("chunk")
            if self.within is not None and h.get("token") == self.within:
                continue                         # (the run this writer's frames belong to)
            if c is not None and self.chunk is not None and not (
                    c[1] < self.chunk[0] or self.chunk[1] < c[0]):
                return (f"an ocl-tonemap {h.get('command', 'apply')} (pid {h.get('pid')}) "
                        f"of this shot is writing {_frames(c)}, which overlap this "
                        f"one's {_frames(self.chunk)}; wait for it, or give disjoint "
                        "--chunk ranges")
        return None

    def release(self) -> None:
        """Leave: this writer's entry out of the record, the file removed by the last
        one. Again, after a signal cut it short anywhere, it does what is left: the
        descriptor is forgotten only as it is closed."""
        fd = self.fd
        if fd is None:
            return
        try:
            _wait(fd, fcntl.F_WRLCK, RECORD_BYTE)
            if self._same_file(fd):
                if _others_hold(fd, WRITER_BYTE):
                    rec = self._read(fd) or {"holders": []}
                    rec["holders"] = [h for h in rec.get("holders", [])
                                      if h.get("token") != self.token]
                    self._write(fd, rec)
                else:
                    os.unlink(self.path)
        except (OSError, FrameError):
            pass
        self.fd = None
        _HELD.discard(self)
        try:
            os.close(fd)                             # (every lock of this descriptor goes)
        except OSError:
            pass

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
        return False


#: The locks this process holds: a signal landing as a run ends may cut a release
#: short; the command's last step releases what is left (:func:`release_held`).
_HELD: set = set()


def release_held() -> None:
    """Release every lock still held (the command's exit, after a signal)."""
    for lock in list(_HELD):
        lock.release()


def output_lock(output: str, command: str, shot=None, chunk=None,
                within: str | None = None) -> OutputLock | None:
    """The lock of an output frame pattern (None: a still, whose write is atomic)."""
    if not is_sequence(output):
        return None
    return OutputLock(lock_path(output), output, command, shot, chunk,
                      why="wait for it, or give another OUTPUT", within=within)


def export_lock(folder: str, command: str, shot=None, chunk=None) -> OutputLock:
    """The lock of an OCIO view export's folder (``--ocio-export DIR``)."""
    return OutputLock(lock_path(folder, "ocio-export"), folder, command, shot, chunk,
                      why="wait for it, or give another --ocio-export folder")


def is_lock_name(name: str) -> bool:
    return name.startswith(".") and name.endswith(".lock")


def mode_kind(path: str) -> str | None:
    """What is at ``path`` if it is not a regular file (no link followed)."""
    try:
        st = os.lstat(path)
    except OSError:
        return None
    return "a symbolic link" if stat.S_ISLNK(st.st_mode) else file_kind(st.st_mode)
