"""The state written after every frame, and what a resumed run starts from; the
temporary files a killed run left behind."""

from __future__ import annotations

import logging
import os
import re
import stat

from ..io.imageio import FrameError

from ..io.imagewrite import output_folder
from ..io.patterns import is_sequence, same_file, without_frame_token
from ..pipeline.state import AdaptationState
from ..io.state_files import load_state
from .locks import OutputLock, export_lock, output_lock
from .locks import folders_to_make as _missing_folders
from .locks import release_held as release_output_locks
from .options import RUN_KEY, JobOptions, run_fingerprint

log = logging.getLogger("ocl_tonemap")


class RunLock:
    """The locks of a run (``locks.OutputLock``), held for the whole run: on
    ``.<state file>.lock`` beside its checkpoint, and for a sequence on its output
    frames, ``.<output pattern without its frame number>.frames.lock`` beside them
    (``out/o.####.png`` -> ``out/.o.png.frames.lock``): a second writer of the same
    state, or of the same output frames (another run, an ``apply`` of a shot, a Dask
    run), is refused in one line naming the file and the other writer's pid rather
    than mixing its frames and state with the first one's. Removed when the run ends
    (a lock left by a killed run is free: the system released it). A still takes no
    output lock (its write is atomic, and it makes no side file). ``shot``/``chunk``:
    the output lock of a shot's writer (``locks.OutputLock``), which the other
    chunks of the same shot share."""

    def __init__(self, state_path: str | None, output: str | None = None,
                 command: str = "run", shot=None, chunk=None, export: str | None = None):
        self.state_path = state_path
        self.output = output if output is not None and is_sequence(output) else None
        self.locks: list = []
        if self.output is not None:
            self.locks.append(output_lock(self.output, command, shot, chunk))
        if export:
            self.locks.append(export_lock(export, command, shot, chunk))
        if state_path:
            d, name = os.path.split(os.path.abspath(state_path))
            path = os.path.join(d, f".{name}.lock")
            if all(path != q.path for q in self.locks):
                self.locks.append(OutputLock(
                    path, path, command, why="wait for it, or give another OUTPUT or "
                    "--state-out"))
        #: the state's lock file (the first run's, for the messages and the tests)
        self.path = self.locks[-1].path if self.locks else None
        #: the folders the lock made (removed again when the run leaves them empty)
        self.made: list = []

    @property
    def fd(self):                               # (held: any lock)
        return next((q.fd for q in self.locks if q.fd is not None), None)

    def __enter__(self):
        try:
            for f, what in ((self.output, "output"), (self.state_path, "state's")):
                if f:
                    self.made += _missing_folders(f)
                    output_folder(f, None, what)
            for q in self.locks:
                q.acquire()
        except BaseException:
            self.release()
            raise
        _HELD.add(self)
        return self

    def __exit__(self, *exc):
        self.release()
        return False

    def release(self) -> None:
        """Remove the lock files and let the locks go; again, after a signal cut it short
        anywhere, it does what is left (a second unlink or close: nothing)."""
        for q in self.locks:
            q.release()
        made, self.made = self.made, []
        for d in made:                  # (deepest first) a refused run leaves no folder
            try:
                os.rmdir(d)
            except OSError:
                pass
        _HELD.discard(self)


#: The run locks this process holds: a signal landing as a run ends may cut
#: ``RunLock.__exit__`` short; the command's last step releases what is left
#: (:func:`release_held`), so no lock file outlives the run.
_HELD: set = set()


def release_held() -> None:
    """Release every run lock still held (the command's exit, after a signal), and
    every shot writer's lock (``locks.release_held``)."""
    for lock in list(_HELD):
        lock.release()
    release_output_locks()


def checkpoint_path(opts: JobOptions) -> str:
    """Where the state is checkpointed after every frame: ``--state-out``, else the
    output name without its frame number + ``.state.json``
    (``out/shot.####.png`` -> ``out/shot.png.state.json``)."""
    if opts.state_out:
        return opts.state_out
    d, b = os.path.split(opts.output)
    b = without_frame_token(b)
    root, dot, ext = b.rpartition(".")
    if not dot:
        root, ext = b, ""
    root = root.rstrip("._-") or "ocl-tonemap"
    return os.path.join(d, f"{root}.{ext}.state.json" if ext else f"{root}.state.json")


def resume_point(opts: JobOptions, jobs, ckpt: str, operator: str):
    """(state to start from, jobs still to do) for ``--resume``."""
    if not os.path.exists(ckpt):
        log.warning("--resume: no checkpoint %s; starting from the first frame", ckpt)
        return None, jobs
    st = load_state(ckpt)
    if st.operator != operator:
        raise ValueError(f"--resume: the checkpoint {ckpt} belongs to operator {st.operator!r}, "
                         f"not {operator!r}")
    was, now = st.extra.get(RUN_KEY), run_fingerprint(opts)
    if isinstance(was, dict):
        # keys added since the checkpoint was written are not compared
        diff = [k for k in sorted(was) if was.get(k) != now.get(k)]
        if diff:
            raise ValueError("--resume: the checkpoint " + ckpt + " was written by a run with "
                             "other settings (" + "; ".join(
                                 f"{k}: {was.get(k)!r} then, {now.get(k)!r} now" for k in diff)
                             + "); resume with the same options, or start again without "
                             "--resume")
    if st.frame is None:
        raise ValueError(f"--resume: the checkpoint {ckpt} has no frame number (a still); "
                         "run it again")
    frames = [j[0] for j in jobs if j[0] is not None]
    if st.frame not in frames:
        shot = (f"{frames[0]}-{frames[-1]}" if len(frames) > 1 else str(frames[0])) \
            if frames else "none"
        raise ValueError(f"--resume: the checkpoint {ckpt} is at frame {st.frame}, which is "
                         f"not a frame of this shot (frames {shot}, {len(frames)} of them); "
                         "give the frames of the run that wrote it, or start again without "
                         "--resume")
    st.extra.pop(RUN_KEY, None)
    todo = [j for j in jobs if j[0] is not None and j[0] > st.frame]
    log.info("resuming after frame %d from %s: %d of %d frame(s) left", st.frame, ckpt,
             len(todo), len(jobs))
    return st, todo


def load_state_in(opts: JobOptions) -> AdaptationState | None:
    """``--state-in``, without the settings of the run that wrote it (``RUN_KEY``)."""
    if not opts.state_in:
        return None
    st = load_state(opts.state_in)
    st.extra.pop(RUN_KEY, None)
    return st


def checkpoint_state(tm, fingerprint: dict) -> AdaptationState:
    """The state after a frame, with the run's settings (checked by --resume)."""
    st = tm.state
    st.extra[RUN_KEY] = fingerprint
    return st


#: What ``--plot`` writes (matplotlib's raster and vector formats, by extension).
PLOT_FORMATS = ("png", "pdf", "svg", "jpg", "jpeg", "tif", "tiff", "webp", "eps", "ps")


def check_state_paths(jobs, paths, plot: str | None = None, inputs=()) -> None:
    """The state files must not be an input or an output (their folder is made
    where missing); ``--plot`` must be none of the run's inputs, outputs, state
    files or other files it reads (``inputs``: --state-in, --cuts ...)."""
    files = {p for _, i, o, _ in jobs for p in (i, o)}
    for p in paths:
        output_folder(p, None, "state's")
        if os.path.isdir(p):
            raise FrameError(p, None, "is a folder; the state is a file (give a file name, "
                             "e.g. state.json)")
        for q in files:
            if same_file(p, q):
                raise FrameError(p, None, "the state file would overwrite an input or output "
                                 "frame; choose another --state-out")
    if plot:
        for q in list(files) + [p for p in paths if p] + [p for p in inputs if p]:
            if same_file(plot, q):
                raise FrameError(plot, None, f"--plot would overwrite {q}, a file of this "
                                 "run; choose another name")
        ext = os.path.splitext(plot)[1].lower().lstrip(".")
        if ext not in PLOT_FORMATS:
            raise FrameError(plot, None, f"--plot writes {', '.join(PLOT_FORMATS)} (by the "
                             f"extension; got {'.' + ext if ext else 'none'})")
        if os.path.isdir(plot):
            raise FrameError(plot, None, "--plot: is a folder; give a file name (plot.png)")
        output_folder(plot, None, "plot's")


def remove_stale_temps(jobs, state_paths=(), folders=()) -> None:
    """Temporary files a killed earlier run may have left beside the outputs and
    the state files (``.<name>.tmp<pid>[<ext>]``, only those of this run's files,
    and only when that process is gone), and in ``folders`` that are the tool's own
    (a shot store's): any temporary of its naming there. Only regular files: a
    link, a FIFO or a folder of that name is not one of ours."""
    from pathlib import Path
    mine: dict = {}
    for _, _, o, _ in jobs:
        mine.setdefault(os.path.dirname(os.path.abspath(o)), set()).add(Path(o).stem)
    prefixes: dict = {}
    for sp in state_paths:                  # the JSON itself and its per-pixel planes
        d, name = os.path.split(os.path.abspath(sp))
        mine.setdefault(d, set()).add(name)
        prefixes.setdefault(d, []).append(name[:-5] + ".pixels." if name.endswith(".json")
                                          else name + ".pixels.")
    for d in folders:
        prefixes.setdefault(os.path.abspath(str(d)), []).append("")
        mine.setdefault(os.path.abspath(str(d)), set())
    rx = re.compile(r"^\.(.+)\.tmp(\d+)(\.[A-Za-z0-9]+)?$")
    for d, stems in mine.items():
        try:
            names = os.listdir(d)
        except OSError:
            continue
        for name in names:
            m = rx.match(name)
            if not m or int(m.group(2)) == os.getpid():
                continue
            if m.group(1) not in stems and not any(m.group(1).startswith(pfx)
                                                   for pfx in prefixes.get(d, ())):
                continue                       # not a temporary of one of this run's files
            try:
                os.kill(int(m.group(2)), 0)
                continue                       # that process is alive: not ours to remove
            except PermissionError:
                continue                       # alive, another user's
            except (ProcessLookupError, OverflowError):
                pass
            path = os.path.join(d, name)
            try:
                if not stat.S_ISREG(os.lstat(path).st_mode):
                    continue                   # (we make regular files only)
                os.unlink(path)
            except OSError:
                pass
