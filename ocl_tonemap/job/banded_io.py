"""A frame too large to hold whole: read, mapped and written in row bands."""

from __future__ import annotations

import logging
import os
from typing import TYPE_CHECKING

import numpy as np

from ..pipeline.alpha import restore_alpha, straight_colour
from ..colour.calibration import LogAverage
from ..io.channels import spectral_channels
from ..io.imageio import BandReader, FrameError, illuminant_from_metadata, max_frame_bytes
from ..io.imagewrite import BandWriter
from .frame import FrameInput, output_metadata, remember_auto
from .options import JobOptions, output_is_linear
from .sequence import frame_time
from .setup import RunSetup

if TYPE_CHECKING:                                  # annotations only
    from ..pipeline import Tonemapper

log = logging.getLogger("ocl_tonemap")

#: Host memory of the whole-frame path, in frames of float32 RGB (measured: 12x for
#: pattanaik00 and durand00 at 6000x4000, PoCL's device buffers included), and of the
#: streaming path per pixel of a band (reads, colour, device buffers, encode, write).
WHOLE_FRAME_COPIES = 12.0


STREAM_BYTES_PER_PIXEL = 160.0


def stream_rows(opts: JobOptions, tm: Tonemapper, inp: str, f) -> int | None:
    """Rows per band when this frame is to be streamed, else None: when it would
    take more than ``--max-memory`` whole (or more than the machine can hold),
    for operators that can stream (``Tonemapper.can_stream``)."""
    spec, budget = _over_budget(opts, inp)
    if spec is None:
        return None
    frame_bytes = float(spec.width) * spec.height * 12.0
    why = tm.can_stream()
    if why:
        log.warning("%s: %.0f MiB would be needed whole, over the budget of %.0f MiB, but it "
                    "cannot be streamed (%s)", inp, WHOLE_FRAME_COPIES * frame_bytes / 2**20,
                    budget / 2**20, why)
        return None
    rows = int(max(1, min(spec.height, (budget / 4) // (STREAM_BYTES_PER_PIXEL * spec.width))))
    log.info("%s: streamed in bands of %d rows (budget %.0f MiB)", inp, rows, budget / 2**20)
    return rows


def read_whole(opts: JobOptions, inp: str) -> bool:
    """Whether this frame is read whole whatever the operator (within the budget, a
    spectral image, or a file whose header cannot be read: its read says why), so it
    can be read before the run is set up."""
    return _over_budget(opts, inp)[0] is None


def _over_budget(opts: JobOptions, inp: str):
    """(the file's spec, the budget in bytes) when the frame would take more than the
    budget whole, else (None, budget)."""
    budget = opts.max_memory * 2**20 if opts.max_memory else max_frame_bytes()
    if opts.max_memory is None and not os.path.exists(inp):
        return None, budget
    if os.path.exists(inp) and not os.path.isfile(inp):
        return None, budget      # a FIFO is never opened: read_frame refuses it in words
    try:
        import OpenImageIO as oiio
        i = oiio.ImageInput.open(inp)
        if i is None:
            oiio.geterror()          # (this thread's; read_frame reports it properly)
            return None, budget
        spec = i.spec()
        i.close()
    except Exception:  # noqa: BLE001 -- read_frame reports it properly
        return None, budget
    if spectral_channels(spec.channelnames):
        return None, budget                           # spectra are read whole
    frame_bytes = float(spec.width) * spec.height * 12.0
    if WHOLE_FRAME_COPIES * frame_bytes <= budget or spec.width < 1:
        return None, budget
    return spec, budget


class WorkingBands:
    """A frame file as working-space bands for ``Tonemapper.process_stream``: rows
    read on demand, colour converted, colour straightened (divided by alpha)
    where it was premultiplied; the alpha of the last bands is kept for the sink."""

    def __init__(self, reader, colour, ic, premultiplied: bool):
        self.reader, self.colour, self.ic = reader, colour, ic
        self.premultiplied = premultiplied
        self.shape = reader.shape
        self._alpha: dict = {}

    def __getitem__(self, sl: slice) -> np.ndarray:
        y0, y1 = sl.start or 0, sl.stop
        band = self.colour.convert_input(self.reader.read(y0, y1), self.ic)
        if band.shape[2] == 4:
            band, alpha = straight_colour(band, self.premultiplied)
            self._alpha = {y0: alpha}
        return band

    def alpha(self, y0: int):
        return self._alpha.get(y0)


def stream_frame(run: RunSetup, tm: Tonemapper, inp, outp, f, held, rows, fps, t_prev,
                  measure_only: bool = False, weights: dict | None = None):
    """One frame read, mapped and written in bands of ``rows`` rows; returns (time, info,
    fps). ``measure_only``: its statistics only, (time, FrameStats, fps, illuminant
    hint), nothing written (``shot/passes.py``)."""
    reader = BandReader(inp, f, run.opts.channels)
    writer = None
    try:
        fr = reader.header
        t, fps = frame_time(fr, f, held, fps, t_prev)
        ic = run.input_colour(fr, inp)
        if fr.channel_note:
            run.once(logging.WARNING, "%s: %s", inp, fr.channel_note)
        h, w, _ = reader.shape

        def logavg():                 # auto:LEVEL: the whole frame's sample, band by band
            acc = LogAverage(h * w)
            for y0 in range(0, h, rows):
                acc.add(run.colour.convert_input(reader.read(y0, min(h, y0 + rows)), ic))
            la = acc.result()
            return np.full((1, 1, 3), la if la else 0.0, np.float32)

        scale, why = run.calibrate(fr, logavg)
        remember_auto(tm, run)
        premult = run.premultiplied(fr)
        fin = FrameInput(None, None, ic.describe(), scale, why,
                         illuminant_from_metadata(fr.spec), premult)
        source = WorkingBands(reader, run.colour, ic, premult)
        linear = output_is_linear(run.opts, outp)
        has_alpha = reader.shape[2] == 4

        def start(info):              # the frame's record is known: open the writer
            nonlocal writer
            extra = {"ocltm:held_from": os.path.basename(inp)} if held else {}
            extra["ocltm:streamed"] = f"row bands of {rows}"
            meta, out_cs, chroma, white, straight = output_metadata(
                run, tm, fr, fin, info, extra, linear, has_alpha, fps)
            writer = BandWriter(outp, fr.spec, 4 if has_alpha else 3, out_cs, meta,
                                run.opts.out_bits, f, chroma, white, straight,
                                run.opts.png_level, run.opts.png_filter)

        def sink(y0, band):
            px = run.colour.linear(band) if linear else run.colour.encode_fast(band)
            a = source.alpha(y0)
            if a is not None:
                px = restore_alpha(px, a)
            writer.write(y0, px)

        # bands of ``rows`` rows; per-pixel planes of local operators (their state and
        # levels) go to a file beside the output, read and written by bands
        # (backends/planes.py)
        with tm.backend.banded(rows * w, os.path.dirname(os.path.abspath(outp))):
            if measure_only:
                stats = tm.process_stream(source, None, time_s=t, frame_number=f,
                                          luminance_scale=scale, illuminant=fin.illuminant,
                                          measure_only=True, weights=weights)
                return t, stats, fps, fin.illuminant
            info = tm.process_stream(source, sink, time_s=t, frame_number=f,
                                     luminance_scale=scale, illuminant=fin.illuminant,
                                     start=start)
        writer.commit()
        writer = None
        return t, info, fps
    except FrameError:
        raise
    except Exception as exc:
        raise FrameError(inp, f, exc) from exc
    finally:
        if writer is not None:
            writer.abort()
        reader.close()
