"""The three passes of a shot on Dask (``dask.distributed``).

``ocl-tonemap run IN OUT --scheduler dask --workers N`` starts a ``LocalCluster``
of N worker processes (one thread each: a worker is one OpenCL queue);
``--scheduler tcp://HOST:PORT`` uses a running cluster whose workers see the same
storage (inputs, outputs and the shot store). Each worker process holds one
OpenCL context (:class:`OpenCLWorker`, a worker plugin: made when the worker
starts, reused by every task it runs).

measure   one task per chunk of ``chunk`` frames, in parallel; a retried task
          skips the frames whose statistics are already stored;
integrate one task, after every measure task (a local cluster: in the calling
          process, on every core, while the workers wait);
apply     one task per chunk, in parallel, each starting at a per-pixel keyframe
          (keyframes are written every ``chunk`` frames).

A task that fails is retried ``retries`` times (a lost worker, a transient read
error); a frame that still fails ends the run with its file and frame named, as
in a serial run. Outputs are written as the serial run writes them: to a
temporary name, then renamed.

What the tasks log (the ``ocl_tonemap`` logger: warnings and errors, the workers'
level) goes back with each task's result, or its failure, and the client says each
record once a run, as the serial run does, with the command line's prefix
(:func:`says_once_a_run`); the workers' own stderr says none of it.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import sys
import time

from ..base import safeio
from ..backends.opencl.runtime import get_runtime
from ..io.imageio import FrameError, one_line
from ..job.options import JobResult
from ..models.photometry import RepairCounts
from . import passes

log = logging.getLogger("ocl_tonemap")

try:                                       # the plugin's base class, when Dask is there
    from distributed.diagnostics.plugin import WorkerPlugin as _WorkerPlugin
except ImportError:                        # pragma: no cover -- `pip install ocl-tonemap[dask]`
    _WorkerPlugin = object


class OpenCLWorker(_WorkerPlugin):
    """One OpenCL context per Dask worker process, created when the worker starts
    (``get_runtime`` keeps it for the process: every task's backend uses it).
    ``pocl_threads``: PoCL's thread count in the worker (several PoCL workers on
    one machine otherwise each start a thread per core)."""

    name = "ocl-tonemap-opencl"

    def __init__(self, device: str | None = None, pocl_threads: int | None = None):
        self.device = device
        self.pocl_threads = pocl_threads

    def setup(self, worker=None):
        if self.pocl_threads:
            os.environ.setdefault("POCL_MAX_PTHREAD_COUNT", str(int(self.pocl_threads)))
        get_runtime(self.device)


def _worker_logging() -> None:
    logging.getLogger("ocl_tonemap").setLevel(logging.WARNING)
    # a failed task is reported once, by the client, in one line: not as the worker's
    # own "Compute Failed" record with its traceback
    for name in ("distributed.worker", "distributed.core", "distributed.utils"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _worker_name() -> str:
    try:
        from distributed import get_worker
        return str(get_worker().address)
    except Exception:  # noqa: BLE001 - not in a worker
        return "?"


#: Distinct log records a task brings back at most (a run's warnings are a few).
TASK_RECORDS = 200


class _TaskRecords(logging.Handler):
    """The ``ocl_tonemap`` records said while a task runs in this worker, as
    (level, text) once each: they go back to the client with the task's result. Being
    the logger's handler, it keeps them from Python's last-resort handler, which
    printed them on the worker's stderr without our prefix (issue 65)."""

    def __init__(self):
        super().__init__()
        self.said: dict = {}

    def emit(self, record):
        try:
            text = record.getMessage()
        except Exception:  # noqa: BLE001 - a record that does not format (as without us)
            self.handleError(record)
            return
        if len(self.said) < TASK_RECORDS:
            self.said.setdefault((record.levelno, text))

    def records(self) -> list:
        return list(self.said)


@contextlib.contextmanager
def _kept_records():
    """:class:`_TaskRecords` on the ``ocl_tonemap`` logger while the block runs (a
    worker with several threads: each task's handler sees every thread's records;
    the client says each once)."""
    lg = logging.getLogger("ocl_tonemap")
    kept = _TaskRecords()
    lg.addHandler(kept)
    try:
        yield kept
    finally:
        lg.removeHandler(kept)


class TaskFailed(FrameError):
    """A task's failure (a FrameError: its file and frame) with the records the task
    said before it (pickled with it to the client)."""

    def __init__(self, path, frame, why, records=()):
        super().__init__(path, frame, why)
        self.records = list(records)

    def __reduce__(self):
        return (type(self), (self.path, self.frame, self.why, self.records))


class _OnceARun(logging.Filter):
    """Each record once (its level and text): the client's own and its tasks'."""

    def __init__(self):
        super().__init__()
        self.seen: set = set()

    def filter(self, record) -> bool:
        key = (record.levelno, record.getMessage())
        if key in self.seen:
            return False
        self.seen.add(key)
        return True


def says_once_a_run(fn):
    """``fn`` (a run on Dask) with the ``ocl_tonemap`` logger saying each record once
    while it runs: a warning every task met (the input colour assumed, a frame held)
    comes once, as in the serial run, where :class:`~ocl_tonemap.job.setup.RunSetup`
    says it once a run."""
    @functools.wraps(fn)
    def run(*args, **kwargs):
        once = _OnceARun()
        log.addFilter(once)
        try:
            return fn(*args, **kwargs)
        finally:
            log.removeFilter(once)
    return run


def _say(records) -> None:
    """The records a task brought back, through the ``ocl_tonemap`` logger."""
    for level, text in records:
        log.log(level, "%s", text)


def _task(what: str, chunk, fn):
    """Run one task's pass: (its value, the records it said). What fails comes back as
    one FrameError naming the pass, the frames and the worker (a FrameError of the
    pass keeps its file and frame), with the records said before."""
    _worker_logging()
    with _kept_records() as kept:
        try:
            return fn(), kept.records()
        except FrameError as exc:
            raise TaskFailed(exc.path, exc.frame, f"{exc.why} ({what} on worker "
                             f"{_worker_name()})", kept.records()) from None
        except Exception as exc:  # noqa: BLE001 - the client shows it in one line
            span = f"frames {chunk[0]}-{chunk[1]}" if chunk else "the shot"
            raise TaskFailed(f"{what} of {span}", None, f"{one_line(exc, True)} (on worker "
                             f"{_worker_name()})", kept.records()) from None


def _measure_task(opts, store, chunk):
    """(frames measured, set-up seconds, task seconds) of one chunk."""
    def go():
        t = time.perf_counter()
        timing: dict = {}
        done = passes.measure(opts, store, chunk, timing=timing)
        return done, timing.get("setup", 0.0), time.perf_counter() - t
    return _task("measure", chunk, go)


def _integrate_task(opts, store, keyframe_every):
    return _task("integrate", None, lambda: passes.integrate(opts, store, keyframe_every))


def _apply_task(opts, store, chunk, within=None):
    def go():
        t = time.perf_counter()
        res = passes.apply(opts, store, chunk, within)
        return (res.frames, res.outputs, res.repairs.as_dict(), res.setup_s,
                time.perf_counter() - t)
    return _task("apply", chunk, go)


def task_overheads(workers: int, timing: dict, tasks: dict) -> dict:
    """Per pass: {"tasks", "setup_s" (mean set-up in a task before its first frame:
    checks, the run's set-up, the store), "dask_s" (mean time a task was not running
    in a worker: the pass's wall time on ``workers`` less the tasks' own, per task;
    scheduling, transfers and idle workers at the pass's end)}."""
    out = {}
    for name, got in tasks.items():
        n = max(len(got), 1)
        busy = sum(w for _, w in got)
        out[name] = {"tasks": len(got), "setup_s": sum(s for s, _ in got) / n,
                     "dask_s": max(0.0, timing.get(name, 0.0) * workers - busy) / n}
    return out


def overhead_line(tasks: dict) -> str:
    """"measure 8 tasks, 0.03 s set-up + 0.01 s Dask a task; apply ..." (the run's
    summary line)."""
    return "; ".join(f"{k} tasks {v['tasks']}: {v['setup_s']:.2f} s set-up + "
                     f"{v['dask_s']:.2f} s Dask a task" for k, v in tasks.items())


def load_security(path: str):
    """Dask's ``Security`` from ``--scheduler-security FILE``: YAML or JSON with
    ``ca``, ``cert`` and ``key`` (PEM files; relative paths from the file's folder)."""
    import json

    text = safeio.read_text(path, "--scheduler-security", 1 << 20)
    try:
        import yaml
        doc = yaml.safe_load(text)
    except ImportError:                    # pragma: no cover -- PyYAML comes with Dask
        doc = json.loads(text)
    except Exception as exc:  # noqa: BLE001 - yaml's own errors
        raise ValueError(f"--scheduler-security {path}: not YAML or JSON ({exc})") from None
    if not isinstance(doc, dict) or not all(isinstance(doc.get(k), str) for k in ("ca", "cert")):
        raise ValueError(f"--scheduler-security {path}: needs ca and cert (and key, unless "
                         "the cert file holds it): paths of PEM files")
    base = os.path.dirname(os.path.abspath(path))
    files = {}
    for k in ("ca", "cert", "key"):
        v = doc.get(k)
        if v is None:
            continue
        if not isinstance(v, str):
            raise ValueError(f"--scheduler-security {path}: {k} must be a path")
        p = v if os.path.isabs(v) else os.path.join(base, v)
        safeio.regular_file(p, f"--scheduler-security {k}")
        files[k] = p
    from distributed.security import Security
    return Security(tls_ca_file=files["ca"], tls_client_cert=files["cert"],
                    tls_client_key=files.get("key"), require_encryption=True)


def worker_environ() -> dict:
    """Dask's environment for the worker processes it spawns, without its
    ``MALLOC_TRIM_THRESHOLD_`` (65536): a fixed trim threshold turns off glibc's
    dynamic mmap threshold, so every frame-sized array is mapped and unmapped again
    (page faults on each new one). Measured (issue 59): a measure task over 60
    frames at 320x180 took 1.62 s in a worker with it and 1.06 s without (1.12 s
    in the calling process). Workers of a cluster started elsewhere: start them
    without it (``DASK_DISTRIBUTED__NANNY__PRE_SPAWN_ENVIRON__MALLOC_TRIM_THRESHOLD_``
    left unset is not enough: set it to a large value or start the nanny with a
    configuration that drops it, docs/scale-out.md)."""
    import dask
    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    return env


def _tls_configured() -> bool:
    import dask
    return bool(dask.config.get("distributed.comm.tls.ca-file", None))


def _client(scheduler: str | None, workers: int, pocl_threads: int | None,
            security: str | None = None):
    """(Client, cluster we started or None). ``security``: ``--scheduler-security``."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise RuntimeError("--scheduler dask needs Dask: pip install 'ocl-tonemap[dask]' "
                           "(dask[distributed])") from None
    for name in ("distributed", "dask"):          # their INFO lines are not ours
        logging.getLogger(name).setLevel(max(logging.WARNING, logging.getLogger(name).level))
    import warnings                               # (nor a dashboard's port moved aside)
    warnings.filterwarnings("ignore", category=UserWarning, module=r"distributed(\..*)?$")
    if scheduler in (None, "dask", "local"):
        import dask
        env = {"POCL_MAX_PTHREAD_COUNT": str(pocl_threads)} if pocl_threads else {}
        with dask.config.set({"distributed.nanny.pre-spawn-environ": worker_environ()}):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.CRITICAL,
                                   env=env)
        return Client(cluster), cluster
    if not str(scheduler).startswith(("tcp://", "tls://", "inproc://", "ucx://", "ws://")):
        raise ValueError(f"--scheduler must be dask (a local cluster) or a scheduler address "
                         f"such as tcp://HOST:8786 (got {scheduler!r})")
    sec = load_security(security) if security else None
    if sec is None and str(scheduler).startswith("tls://") and not _tls_configured():
        raise ValueError(f"--scheduler {scheduler}: a TLS scheduler needs certificates: "
                         "--scheduler-security FILE (ca, cert, key), or Dask's "
                         "distributed.comm.tls configuration")
    try:
        return Client(scheduler, security=sec, timeout="20s"), None
    except (OSError, TimeoutError) as exc:
        raise RuntimeError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    except MemoryError:           # a peer that is no Dask scheduler (its handshake a size)
        raise RuntimeError(f"--scheduler {scheduler}: what answers there is not a Dask "
                           "scheduler (its handshake is not Dask's)") from None


def _gather(futures, what: str, progress: bool, t0: float):
    """Wait for the futures in completion order, showing progress; the first
    failure is raised (its FrameError names the file and frame) and the rest cancelled.
    The records the tasks said are said here, after the progress line."""
    from dask.distributed import as_completed
    out, n, said = {}, len(futures), []
    try:
        for k, fut in enumerate(as_completed(futures), 1):
            try:
                out[fut.key], got = fut.result()
                said += got
            except Exception as exc:  # noqa: BLE001 - our tasks raise FrameError already
                said += getattr(exc, "records", [])
                if isinstance(exc, FrameError):
                    raise
                raise RuntimeError(f"task {fut.key}: {one_line(exc, True)}") from None
            if progress:
                sys.stderr.write(f"\r{what}: {k}/{n} task(s), {time.perf_counter() - t0:6.1f} s")
                sys.stderr.flush()
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise
    finally:
        if progress:
            sys.stderr.write("\n")
        _say(said)
    return [out[f.key] for f in futures]


#: A local operator's Dask tasks hold at least this many frames where the shot has as
#: many for each worker: each apply task starts by reading a per-pixel keyframe and
#: integrate writes one a chunk (ledda04 at 1080p: ~0.3 s each, against ~0.2 s a frame
#: of apply; chunks of 4 frames made 30 frames on 2 workers 2.5x the serial run, issue
#: 59). Global operators' states are a few KiB: their chunks stay small.
LOCAL_CHUNK_FRAMES = 16


def default_chunk(frames: int, workers: int, local: bool) -> int:
    """Frames a task: four tasks a worker (load balance, retries), and for a local
    operator at least :data:`LOCAL_CHUNK_FRAMES` (at most one task a worker's share)."""
    size = math.ceil(frames / (4 * workers))
    if local:
        size = max(size, min(math.ceil(frames / workers), LOCAL_CHUNK_FRAMES))
    return max(1, size)


@says_once_a_run
def run_distributed(opts, scheduler: str | None = "dask", workers: int = 2,
                    chunk: int | None = None, store: str | None = None,
                    retries: int = 2, progress: bool = False, pocl_threads: int | None = None,
                    security: str | None = None):
    """The shot on Dask: measure -> integrate -> apply. Returns a
    :class:`~ocl_tonemap.job.options.JobResult` (frames, outputs, repairs, seconds)
    with the seconds of each pass in ``passes``."""
    t0 = time.perf_counter()
    if not (isinstance(workers, int) and workers >= 1):
        raise ValueError(f"--workers must be >= 1 (got {workers})")
    if opts.resume or opts.state_out or opts.plot:
        raise ValueError("--resume, --state-out and --plot belong to the serial run; a "
                         "distributed run keeps the state at each chunk's start in its "
                         "--store (states/<frame>.json) and every frame's in the output's "
                         "ocltm:state")
    import dataclasses
    jobs = passes.shot_jobs(opts)              # inputs checked here, before any worker starts
    opts = dataclasses.replace(opts, progress=False)     # (the workers' own: ours is below)
    frames = [j[0] for j in jobs]
    store = store or passes.default_store(opts)
    size = chunk or default_chunk(len(frames), workers, passes.keeps_planes(opts))
    parts = passes.chunks(frames, size)
    # the output frames' lock over the whole shot, shared with its own apply tasks
    # (``within``), refused to any other writer
    lock = passes.shot_lock(opts, store, jobs, "run --scheduler dask")
    lock.__enter__()
    try:
        client, cluster = _client(scheduler, workers, pocl_threads, security)
    except BaseException:
        lock.__exit__(None, None, None)
        raise
    timing = {}
    try:
        if opts.backend == "opencl":
            client.register_plugin(OpenCLWorker(opts.device, pocl_threads))
        t = time.perf_counter()
        timing["start"] = t - t0
        futs = [client.submit(_measure_task, opts, store, c, key=f"measure-{c[0]}-{c[1]}",
                              retries=retries, pure=False) for c in parts]
        measured = _gather(futs, "measure", progress, t0)
        timing["measure"] = time.perf_counter() - t
        t = time.perf_counter()
        if cluster is not None:
            # a local cluster: the serial pass here, on every core (a worker has
            # cores / workers PoCL threads; ledda04's per-pixel step at 1080p took
            # 7.5 s in one of two workers against 3.3 s on the machine, issue 59)
            integ = passes.integrate(opts, store, size)
        else:
            fut = client.submit(_integrate_task, opts, store, size, key="integrate",
                                retries=retries, pure=False)
            integ = _gather([fut], "integrate", progress, t0)[0]
        timing["integrate"] = time.perf_counter() - t
        t = time.perf_counter()
        futs = [client.submit(_apply_task, opts, store, c, getattr(lock, "token", None),
                              key=f"apply-{c[0]}-{c[1]}", retries=retries, pure=False)
                for c in parts]
        done = _gather(futs, "apply", progress, t0)
        timing["apply"] = time.perf_counter() - t
    finally:
        try:
            client.close()
            if cluster is not None:
                cluster.close()
        finally:
            lock.__exit__(None, None, None)
    res = JobResult([], [])
    for fr, outs, rep, _, _ in done:
        res.frames += fr
        res.outputs += outs
        res.repairs += RepairCounts(**rep)
    res.seconds = time.perf_counter() - t0
    res.passes = timing
    res.tasks = task_overheads(workers, timing, {
        "measure": [(s, w) for _, s, w in measured], "apply": [(d[3], d[4]) for d in done]})
    res.cuts = integ.get("cuts", [])
    return res
