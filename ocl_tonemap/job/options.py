"""What a run is asked to do: :class:`JobOptions` (checked when made), what it
returns (:class:`JobResult`), and the parsers of the command line's values."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from ..backends.quality import quality_tier
from ..io.imageio import LINEAR_FORMATS, PNG_FILTERS
from ..models.adrian1989 import ADRIAN_1989
from ..models.photometry import RepairCounts
from ..io.patterns import MAX_FRAME
from ..base.quantities import OBSERVATION_S, RUN, TARGET_ARCMIN
from ..base.safeio import read_text

DEFAULT_FPS = 24.0
#: What a gap in a sequence does (``--missing``).
MISSING_POLICIES = ("error", "hold", "skip")

class Interrupted(RuntimeError):
    """A run stopped by SIGINT/SIGTERM after a complete frame (checkpoint written)."""

    def __init__(self, signum: int, done: int, total: int, last_frame, checkpoint: str | None):
        self.signum, self.done, self.total = signum, done, total
        self.last_frame, self.checkpoint = last_frame, checkpoint
        super().__init__(f"interrupted after {done} of {total} frame(s)")

    @property
    def exit_code(self) -> int:
        return 128 + int(self.signum)


@dataclass
class JobOptions:
    input: str
    output: str
    frames: list[int] | None = None
    fps: float | None = None
    operator: str = "pattanaik00"
    metering: str = "logmean"
    luminance_scale: float | str | None = None    # S, or "auto:LEVEL" (calibration.py)
    exposure: float = 0.0
    colorconfig: str | None = None
    iscolorspace: str | None = None
    display: str | None = None
    view: str | None = None
    display_model: str = "display"
    display_white: float | None = None
    display_peak: float = 1000.0
    display_black: float | None = None
    unpremult: bool | None = None       # None: from the file (oiio:UnassociatedAlpha)
    encode: bool = False                # float outputs: display-encoded, not display-linear
    preadapt: tuple[float, float | None] | None = None
    state_in: str | None = None
    state_out: str | None = None
    backend: str | None = None          # None: the --quality tier's (opencl but for reference)
    device: str | None = None
    out_bits: str | None = None
    plot: str | None = None
    plot_frames: list[int] | None = None
    visibility: str | None = None       # per-frame visibility planes, EXR (job/visibility_out.py)
    visibility_view: str | None = None  # ... its false-colour view over the frame
    target_size: float = TARGET_ARCMIN  # --target-size, arcmin
    observation_time: float = OBSERVATION_S  # --observation-time, s
    adrian: str = ADRIAN_1989.name      # --adrian 1989|rp8 (models/adrian1989.py, D1-D7)
    visibility_type: str = "half"       # --visibility-type half|float: the planes' samples
    veil_halo: bool = False             # --veil-halo: Lveil with the flare's lenticular halo
    target: tuple | None = None         # --target X,Y,SIZE: one target tracked through the shot
    ocio_export: str | None = None      # a folder: the observer as an OCIO view (colour/export.py)
    ocio_export_size: int | str = "auto"    # lattice nodes per axis, or auto
    fov_given: bool = False             # --fov given: a Radiance picture's VIEW does not set it
    fov_source: str = ""                # where the field of view came from (ocltm:fov)
    stills: bool = False                # every frame its own observer (--stills)
    max_band_pixels: int | None = None
    progress: bool = False
    operator_options: dict | None = None
    effects: object | None = None   # effects.EffectSettings; None: the operator's defaults
    missing: str = "error"          # a gap in a sequence: error | hold | skip
    channels: list[str] | None = None   # --channels: names used as R,G,B (or one: luminance)
    png_level: int = 1                  # zlib level of PNG outputs (imageio.PNG_LEVEL)
    png_filter: str = "sub"             # PNG row filter (imageio.PNG_FILTERS)
    max_memory: float | None = None     # MiB: frames that would take more stream in bands
    resume: bool = False            # continue from the checkpoint of an earlier run
    checkpoint: bool = True         # write the state after every frame ...
    checkpoint_every: int = 1       # ... or every N frames (local operators: per-pixel planes)
    overlap_io: bool = True         # read the next frame and write the last one beside the work
    threads: int | None = None      # --threads: decode/encode threads (None: the machine's cores)
    display_encode: str | None = None   # auto | table (device) | ocio (CPU); None: the tier's
    quality: str | None = None      # --quality: draft | balanced (None) | reference
    cuts: list[int] | str | None = None  # --cuts: frames where the eyes start afresh, or "detect"

    def __post_init__(self):
        tier = quality_tier(self.quality)          # the defaults a knob not given takes
        self.quality = tier.name
        self.backend = self.backend or tier.backend
        self.display_encode = self.display_encode or tier.display_encode
        for name, decl in RUN.items():      # each declared value, as its flag checks it
            v = getattr(self, name, None)
            if v is not None:
                setattr(self, name, decl.check(v, "--" + name.replace("_", "-")))
        if self.display_black is not None and self.display_white is not None and \
                not self.display_black < self.display_white:
            raise ValueError(f"--display-black {self.display_black:g} cd/m^2 must be below "
                             f"the display's white (--display-white {self.display_white:g} "
                             "cd/m^2)")
        if self.png_filter not in PNG_FILTERS:
            raise ValueError(f"--png-filter must be {', '.join(PNG_FILTERS)} "
                             f"(got {self.png_filter!r})")
        if self.display_encode not in ("auto", "table", "ocio"):  # colour.DISPLAY_ENCODE_MODES
            raise ValueError(f"--display-encode must be auto, table or ocio "
                             f"(got {self.display_encode!r})")
        if isinstance(self.cuts, str) and self.cuts != "detect":
            raise ValueError(f"cuts must be frame numbers or 'detect' (got {self.cuts!r})")
        if self.missing not in MISSING_POLICIES:
            raise ValueError(f"--missing must be one of {', '.join(MISSING_POLICIES)} "
                             f"(got {self.missing!r})")


@dataclass
class JobResult:
    frames: list[int | None]
    outputs: list[str]
    infos: list = field(default_factory=list)
    repairs: RepairCounts = field(default_factory=RepairCounts)
    seconds: float = 0.0
    export: str = ""                # the OCIO export's summary (--ocio-export)
    setup_s: float = 0.0            # before the first frame: checks, set-up, kernels

    def transfers(self) -> str:
        """Host <-> device transfers per frame, the mean over the frames that made any
        (the run's report; "" without a device)."""
        moved = [i.transfers for i in self.infos if getattr(i, "transfers", None)]
        return transfers_line(moved)


def transfers_line(moved: list) -> str:
    """"up X MiB in N calls, down ..." of frames' transfer dicts (their mean)."""
    if not moved:
        return ""
    mean = {k: sum(m[k] for m in moved) / len(moved) for k in moved[0]}
    return (f"up {mean['up_bytes'] / 2**20:.2f} MiB in {mean['up_calls']:.3g} calls, "
            f"down {mean['down_bytes'] / 2**20:.2f} MiB in {mean['down_calls']:.3g} calls")


#: Largest --cuts file (a list of frame numbers), bytes.
CUTS_CAP = 1 << 20


def parse_cuts(text: str | None):
    """``--cuts``: ``detect``, or a file of frame numbers (whitespace or commas; ``#``
    starts a comment)."""
    if text is None:
        return None
    if text.strip().lower() == "detect":
        return "detect"
    raw = read_text(text, "--cuts", CUTS_CAP)
    body = " ".join(line.split("#", 1)[0] for line in raw.splitlines())
    try:
        cuts = sorted({int(v) for v in body.replace(",", " ").split()})
    except ValueError:
        raise ValueError(f"--cuts {text}: the file must hold frame numbers") from None
    if any(abs(c) > MAX_FRAME for c in cuts):
        raise ValueError(f"--cuts {text}: frame numbers are within +-{MAX_FRAME}")
    return cuts


#: AdaptationState.extra key of the settings a run's frames depend on (--resume checks).
RUN_KEY = "run"


def run_fingerprint(opts: JobOptions) -> dict:
    """The settings that decide a run's frames, kept in its checkpoint: a resumed
    run must use the same to give the same frames."""
    fx = opts.effects
    return {"input": opts.input, "output": opts.output, "operator": opts.operator,
            "fps": opts.fps, "metering": opts.metering,
            "luminance_scale": None if opts.luminance_scale is None else str(opts.luminance_scale),
            "exposure": opts.exposure, "colorconfig": opts.colorconfig,
            "iscolorspace": opts.iscolorspace, "display": opts.display, "view": opts.view,
            "display_model": opts.display_model, "display_white": opts.display_white,
            "display_black": opts.display_black, "backend": opts.backend,
            "quality": opts.quality, "display_encode": opts.display_encode,
            "options": json.loads(json.dumps(opts.operator_options or {}, default=str)),
            "effects": json.loads(json.dumps(fx.as_dict(), default=str))
            if fx is not None else None,
            "missing": opts.missing, "channels": opts.channels, "unpremult": opts.unpremult,
            "encode": opts.encode, "out_bits": opts.out_bits,
            "cuts": opts.cuts if isinstance(opts.cuts, str) else
            (sorted(opts.cuts) if opts.cuts else None)}


def output_is_linear(opts: JobOptions, path: str) -> bool:
    """Float outputs (EXR, .hdr) hold display-linear light unless ``--encode``."""
    return (not opts.encode) and Path(path).suffix.lower() in LINEAR_FORMATS
