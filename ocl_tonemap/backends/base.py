"""The written interface between the job and the backends.

A :class:`Backend` is where a frame's stages run (``reference``: float64 NumPy;
``opencl``: float32 kernels on one device). It hands each operator a
:class:`Schedule`, the object that runs that operator's three phases (measure,
integrate, apply) on it, and offers the pieces the effects and the streaming path
share (the colour stage and metering of a frame or of a band source, device blurs).
The job (``pipeline.Tonemapper``, ``job/``) calls only what is written here;
results come back as values, and settings that hold for a stretch of work (row
bands, where per-pixel planes spill) are given as a ``with`` block
(:meth:`Backend.banded`), never set from outside.

Both are :class:`typing.Protocol` classes: a plugin's schedule (``Operator.schedules``)
needs no base class, only these members. The mixins below are the shared parts
of the built-in schedules (per-pixel state kept on the host, or none).
"""

from __future__ import annotations

import importlib
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, NamedTuple, Protocol

import numpy as np

from ..models import cie146
from ..models import visibility_map as vmap
from ..models.metering import MeteringSpec
from ..models.photometry import RepairCounts
from ..operators.base import Frame, FrameStats
from .planes import band_readable, plane_shape, read_rows


class Later:
    """A value of a frame's record that a device has enqueued and that comes down at the
    frame's next sync point (``opencl/stats.py``): :func:`settle` gives the record
    with it. ``fn()`` gives the value (reading it where it has not come yet)."""

    __slots__ = ("fn",)

    def __init__(self, fn: Callable):
        self.fn = fn


def settle(value):
    """``value`` (a record: dicts, lists, tuples) with each :class:`Later` in it made
    its value."""
    if isinstance(value, Later):
        return settle(value.fn())
    if isinstance(value, dict):
        return {k: settle(v) for k, v in value.items()}
    if type(value) in (list, tuple):
        return type(value)(settle(v) for v in value)
    return value


class Levels(NamedTuple):
    """A frame's colour stage and metering (:meth:`Backend.working`,
    :meth:`Backend.scene_levels`)."""

    rgb: object                        # working RGB in cd/m^2 (host array, device image or None)
    repairs: RepairCounts              # the bad-value policy's counts
    goal: tuple[float, float]          # (G_rod, G_cone), cd/m^2
    illuminant: Callable[[], np.ndarray] | None   # the grey-world estimate, made when called
    max_Y: float | None = None         # the largest working luminance, where known
    proxy: np.ndarray | None = None    # s x s block means of rgb (float64), where asked
    max_Ys: float | None = None        # the largest scotopic luminance, where known


@dataclass
class VisibilityRequest:
    """What :meth:`Backend.visibility` makes one mapped frame's planes from (``run
    --visibility``; the algorithm: ``models/visibility_map.py``)."""

    pixels: np.ndarray          # the frame's working-space pixels as read (host)
    scale: float                # cd/m^2 per unit (the media's gain apart)
    recipe: object              # visibility_map.Recipe: the grids' steps, taps, veil weights
    view: object                # visibility.Viewing: the target and the observer
    op: object                  # the operator (its observer_* methods)
    observer: Callable          # () -> its observer state (op.observer_of; for a local
                                # operator whose state is on a device, a download)
    schedule: object = None     # the operator's schedule (a device's per-pixel state)
    halo: Callable | None = None  # --veil-halo: luminance cells -> the halo's veil there
    dtype: type = np.float16    # the planes' samples


@dataclass
class VisibilityPlanes:
    """One frame's planes: ``data`` H x W x 5 in ``visibility_map.PLANE_NAMES`` order
    (the request's dtype), the veil at its cells' centres (float64, cd/m^2), and how
    many values were beyond half's range and held at its largest."""

    data: np.ndarray
    veil_cells: np.ndarray
    clamped: int = 0

    def plane(self, name: str) -> np.ndarray:
        return self.data[..., vmap.PLANE_NAMES.index(name)]


def planes_on_host(req: VisibilityRequest) -> VisibilityPlanes:
    """The float64 reference of a request (``visibility_map.reference_planes``)."""
    Y = vmap.scene_luminance(req.pixels, req.scale)
    r = req.recipe
    cells = vmap.block_mean(Y, r.veil_step)
    veil = cie146.field_veil(cells, r.veil_weights)
    if req.halo is not None:
        veil = veil + req.halo(cells)
    planes = vmap.reference_planes(req.op, req.observer(), Y, r, req.view, veil)
    data, clamped = vmap.as_samples(planes, req.dtype)
    return VisibilityPlanes(data, planes["veil_cells"], clamped)


class ViewPaint(NamedTuple):
    """How ``run --visibility-view`` paints VL over the shown frame: a pixel's band is
    the number of ``edges`` its VL reaches (0 .. len(edges)); its colour is the shown
    code value (0..1) x ``scale[band]`` + ``add[band]``; band 1 is hatched in ``hatch``
    on every third diagonal of ``step`` pixels."""

    edges: tuple
    scale: tuple
    add: tuple                    # (r, g, b) a band
    hatch: tuple
    step: int

    def as_array(self) -> np.ndarray:
        return np.concatenate([self.edges, self.scale, np.ravel(self.add),
                               self.hatch]).astype(np.float32)


def paint_view(shown: np.ndarray, VL: np.ndarray, paint: ViewPaint) -> np.ndarray:
    """The view's pixels on the host (float32 code values, H x W x 3): the reference of
    :meth:`Backend.visibility_view`."""
    h, w = VL.shape
    band = np.zeros(VL.shape, np.uint8)
    for edge in paint.edges:
        band += VL >= np.float32(edge)
    scale = np.asarray(paint.scale, np.float32)
    add = np.asarray(paint.add, np.float32)
    out = np.clip(np.asarray(shown[..., :3], np.float32), 0.0, 1.0)
    out *= scale[band][..., None]
    out += add[band]
    diagonal = (np.arange(w, dtype=np.int32)[None, :] + np.arange(h, dtype=np.int32)[:, None])
    out[(band == 1) & (diagonal // paint.step % 3 == 0)] = np.asarray(paint.hatch, np.float32)
    return out


class Schedule(Protocol):
    """One operator's phases on one backend."""

    #: Chromatic adaptation's gains go on the cone signals inside :meth:`apply`
    #: (Durand & Dorsey 2000 Eq. 6); False: the job applies them to the scene.
    receptor_gains: bool
    #: Frames can be given as band sources (``source[y0:y1]``) and bands sent to a sink.
    streams: bool
    #: :meth:`apply` can bring its output back as display code values (``encoding``).
    encodes_output: bool
    #: :meth:`apply` maps a frame from statistics read back from a shot's store
    #: (``ScheduleDefaults.applies_stored``).
    applies_stored: bool

    def measure(self, frame: Frame, spec: MeteringSpec,
                want_illuminant: bool = False) -> FrameStats: ...

    def integrate(self, state, stats: FrameStats, dt: float, fresh: bool) -> None: ...

    def apply(self, frame: Frame, state, stats: FrameStats, params, gains=None, sink=None,
              encoding=None) -> np.ndarray | None:
        """The per-pixel map: display-linear float32 (H x W x 3), or the code values of
        ``encoding`` (a ``DeviceOutputEncoding``) where :attr:`encodes_output`; with
        ``sink(y0, band)`` the bands go there in order and None is returned."""

    def pixel_state(self) -> dict | None: ...

    def set_pixel_state(self, pixels) -> None: ...

    def stats_planes(self, stats: FrameStats) -> dict | None:
        """The per-pixel inputs of :meth:`integrate` to store apart from the run (shot
        passes); None where the statistics are scalars."""

    def stats_from_planes(self, stats: FrameStats, planes) -> FrameStats: ...

    def summary(self, stats: FrameStats, params, frame: Frame | None = None) -> dict:
        """The frame's record (metadata, plots); asked before :meth:`apply` when a
        streamed frame's metadata is written with its first band (``frame``: the one
        :meth:`apply` will map)."""


class Backend(Protocol):
    name: str
    #: Pixels per row band on this backend (None: frames are done whole).
    max_band_pixels: int | None
    #: Whether half-float frames go to it as they are (else they are made float32 first).
    half_input: bool

    def describe(self) -> str: ...

    def schedule(self, op) -> Schedule: ...

    def working(self, pixels: np.ndarray, scale: float, spec: MeteringSpec,
                illuminant: bool = True, on_device: bool = False,
                proxy_stride: int = 0, metered: Levels | None = None) -> Levels:
        """Colour stage and metering of a whole frame (``on_device``: ``rgb`` may stay
        on the device, for scene effects that run there; ``proxy_stride`` s > 0: the
        means of the frame's s x s blocks, ``models.metering.block_means``, in the
        same pass). ``metered``: the frame's metering already known (a shot's store):
        the colour stage only, and these Levels with its rgb."""

    def source_proxy(self, shape, stride: int, lim: float) -> np.ndarray | None:
        """Block means (``stride``) of the flare's source part, rgb max(0, 1 - lim / Y),
        of the frame the last :meth:`working` made, where the backend still holds it
        whole; else None (the plan then predicts from the proxy itself)."""

    def source_proxy_ahead(self, shape, stride: int, lim: float) -> None:
        """Start :meth:`source_proxy` of these arguments now, so that the call itself only
        collects it (a device queue: work enqueued after it runs meanwhile); nothing
        where there is no queue."""

    def scene_levels(self, source, scale: float, spec: MeteringSpec,
                     illuminant: bool, proxy_stride: int = 0) -> Levels:
        """Colour stage and metering of a band source (``source[y0:y1]``), without
        keeping its pixels: ``rgb`` is None."""

    def working_rows(self, pixels: np.ndarray, scale: float) -> np.ndarray:
        """The colour stage of some rows: working RGB in cd/m^2, float32, on the host."""

    def banded(self, rows_pixels: int | None, spill_dir: str | None):
        """A ``with`` block in which frames go in bands of ``rows_pixels`` pixels and
        per-pixel planes of banded frames spill to files in ``spill_dir``."""

    def device_runtime(self):
        """The OpenCL runtime where frames are (for display tables on the device), or None."""

    def device_blur(self, max_pixels: int | None = None):
        """The separable blur on the device (``.blur(img, taps, edge)``, ``.blur_axis``),
        or None on the host."""

    def flare_device(self):
        """The fast flare on the device, or None."""

    def purkinje_device(self):
        """The Purkinje shift kernels on the device, or None."""

    def device_image(self, arr):
        """A device array (``pyopencl.array.Array``) as the backend's frame on its device;
        None for anything else (a host backend raises for a device array)."""

    def device_output(self):
        """What makes a frame's output stay on the device (passed where a display encoding
        would be), or None."""

    def device_array(self, pixels):
        """Host pixels as a device array (one upload)."""

    def transfers(self):
        """Host <-> device transfers so far in this thread (``opencl.transfers.Transfers``:
        a frame's are the difference across it), or None without a device."""

    def scale_image(self, img, gains):
        """A device image's RGB times ``gains`` (float32, in place; the image back), or
        None where the backend holds no frame on a device."""

    def threshold_image(self, img, T_rod: float, T_cone: float, beta: float, x_sure: float):
        """A device image's pixels weighted by the chance that they are seen (in place;
        the image back: ``models/absolute_threshold.py``), or None where the backend
        holds no frame on a device."""

    def acuity_encoding(self, encoding, h: int, w: int, taps, t: float, blur):
        """``encoding`` with the acuity blur (``taps``, blended by ``t``) on the device
        before it, or None where the backend cannot."""

    def visibility(self, request: VisibilityRequest) -> VisibilityPlanes:
        """The visibility planes of one mapped frame (``run --visibility``)."""

    def keep_scene_luminance(self, pixels) -> None:
        """Keep what the next colour stage of ``pixels`` makes of them for
        :meth:`visibility` (None: nothing), where the backend can."""

    def visibility_view(self, planes: VisibilityPlanes, shown: np.ndarray, paint: ViewPaint,
                        u8: bool) -> np.ndarray | None:
        """``--visibility-view``'s pixels of the frame whose planes :meth:`visibility`
        made last (``shown``: its output's code values as written, integers or floats),
        uint8 (``u8``) or float32 code values; None where the backend leaves it to the
        host (:func:`paint_view`)."""


class HostBackend:
    """What a backend without a device answers: nothing on a device, frames whole."""

    max_band_pixels: int | None = None
    half_input = False

    def device_runtime(self):
        return None

    def device_blur(self, max_pixels: int | None = None):
        return None

    def flare_device(self):
        return None

    def purkinje_device(self):
        return None

    def scale_image(self, img, gains):
        return None

    def threshold_image(self, img, T_rod, T_cone, beta, x_sure):
        return None

    def transfers(self):
        return None

    def device_image(self, arr):
        if type(arr).__module__.startswith("pyopencl"):
            raise ValueError("a device array (pyopencl.array.Array) needs the OpenCL "
                             "backend: Tonemapper(..., backend='opencl')")
        return None

    def device_output(self):
        return None

    def device_array(self, pixels):
        raise ValueError("device arrays need the OpenCL backend")

    def acuity_encoding(self, encoding, h: int, w: int, taps, t: float, blur):
        return None

    def keep_scene_luminance(self, pixels) -> None:
        return None

    def visibility_view(self, planes, shown, paint, u8: bool):
        return None

    def visibility(self, request: VisibilityRequest) -> VisibilityPlanes:
        """The float64 reference of the planes (:func:`planes_on_host`)."""
        return planes_on_host(request)

    def source_proxy_ahead(self, shape, stride: int, lim: float) -> None:
        return None

    @contextmanager
    def banded(self, rows_pixels: int | None, spill_dir: str | None):
        yield self


class ScheduleDefaults:
    """What a schedule answers unless it says otherwise: scalar statistics only
    (nothing per pixel to store apart), the operator's own frame record."""

    #: Whether :meth:`apply` maps a frame from statistics read back from a shot's
    #: store (``stats_from_planes``; no resident frame: the colour stage runs again
    #: in apply), the same pixels as from its own ``measure`` (a shot's apply pass
    #: then meters nothing twice).
    applies_stored = False

    def stats_planes(self, stats) -> dict | None:
        return None

    def stats_from_planes(self, stats, planes) -> FrameStats:
        return stats

    def summary(self, stats, params, frame=None) -> dict:
        return self.op.summary(params, stats)


class NoPixelState(ScheduleDefaults):
    """Schedules of operators that keep no per-pixel state."""

    def pixel_state(self):
        return None

    def set_pixel_state(self, pixels) -> None:
        if pixels:
            raise ValueError(f"{self.op.name} keeps no per-pixel state")


class PixelStateMixin(ScheduleDefaults):
    """Per-pixel state kept by a schedule: host planes (float64 in the reference).

    ``band_state``: the schedule reads its state by row bands, so a band-readable
    source (``backends/planes.py``) is kept as it is; else it is read whole."""

    planes: tuple = ()
    band_state = False

    def pixel_state(self) -> dict | None:
        if self._host is None:
            return None
        if band_readable(self._host):
            return self._host if getattr(self._host, "spilled", True) else self._host.as_dict()
        return {k: np.array(v, copy=True) for k, v in self._host.items()}

    def set_pixel_state(self, pixels) -> None:
        if pixels is not None:
            names = pixels.names if band_readable(pixels) else tuple(pixels)
            missing = [k for k in self.planes if k not in names]
            if missing and "t_course" in names:
                raise ValueError(f"per-pixel state lacks {', '.join(missing)}: it was saved "
                                 "before ledda04's cones and rods had a clock each (one "
                                 "t_course); rerun the shot from its start")
            if missing:
                raise ValueError(f"per-pixel state lacks {', '.join(missing)}")
            if band_readable(pixels):
                if not self.band_state:
                    h = plane_shape(pixels)[0]
                    pixels = dict(zip(self.planes, read_rows(pixels, self.planes, 0, h)))
            else:
                shapes = {np.shape(pixels[k]) for k in self.planes}
                if len(shapes) != 1 or len(next(iter(shapes))) != 2:
                    raise ValueError("per-pixel state planes must be 2-D and of one size")
                pixels = {k: np.asarray(pixels[k]) for k in self.planes}
        self._host = pixels

    def state_shape(self):
        return None if self._host is None else plane_shape(self._host)

    def check_shape(self, fresh: bool, shape) -> None:
        if fresh:
            return
        have = self.state_shape()
        if have is None:
            raise ValueError(f"this {self.op.name} state has no per-pixel state (was it saved "
                             "with its .pixels.exr side file?)")
        if tuple(have) != tuple(shape):
            raise ValueError(f"per-pixel adaptation state is {have[1]}x{have[0]} but the frame "
                             f"is {shape[1]}x{shape[0]}; local adaptation needs one image size")


def load_schedule(spec: str):
    """``"package.module:Class"`` (relative names start at ocl_tonemap.backends)."""
    mod, _, cls = spec.partition(":")
    module = importlib.import_module(mod, "ocl_tonemap.backends") if mod.startswith(".") \
        else importlib.import_module(mod)
    return getattr(module, cls)
