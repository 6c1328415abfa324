"""What a verified write costs: the read-back of a just-written frame and the two
fsyncs (the file, its folder) against the write itself and a whole frame's time.

One command:
    python -m benchmarks.write_safety [--size 1920x1080] [--reps 7] [--out-dir DIR | --out FILE]

Writes write_safety.md into DIR (default ./benchmark-results; the committed one:
``--out-dir benchmarks/results``).

Per output format (PNG 8-bit, EXR half zip, TIFF 16-bit, JPEG): the median of
``--reps`` of each step of ``imagewrite.write_frame`` on a tone-mapped photograph-like
frame (the tunnel sample's daylight frame through pattanaik00): encoding and
writing to the temporary file, ``verify_written`` (header and last row read
back), ``safeio.commit`` (fsync of the file, rename, fsync of the folder); and
the whole frame (``Tonemapper.process_frame``, OpenCL, the default operator and
model) for scale. The issue's target: read-back and fsyncs under 5% of a frame's
time. Machines are noisy: compare the ratios. The timed writes go to the folder the
results are written to (a real disk, not tmpfs), the files removed after.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import numpy as np
import OpenImageIO as oiio

from benchmarks.lib.outdir import add_out_args, out_path

HERE = os.path.dirname(os.path.abspath(__file__))
FORMATS = ((".png", "8"), (".exr", "half"), (".tif", "16"), (".jpg", "8"))


def _median_ms(fn, reps):
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(ts)


def fs_type(path: str) -> str:
    """The file system type of ``path`` (from /proc/mounts; '?' where unknown)."""
    try:
        best = ("", "?")
        real = os.path.realpath(path)
        with open("/proc/mounts") as fh:
            for line in fh:
                parts = line.split()
                if len(parts) > 2 and real.startswith(parts[1]) and len(parts[1]) > len(best[0]):
                    best = (parts[1], parts[2])
        return f"{best[1]} at {best[0]}"
    except OSError:
        return "?"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--reps", type=int, default=7)
    add_out_args(ap, "write_safety.md")
    a = ap.parse_args(argv)
    out_file = out_path(a, "write_safety.md")
    w, h = (int(v) for v in a.size.lower().split("x"))
    from ocl_tonemap.base import safeio
    from ocl_tonemap.io import imageio, imagewrite
    from ocl_tonemap.pipeline import Tonemapper
    from ocl_tonemap.io.sample import render_frame
    scene = np.ascontiguousarray(render_frame(1.2, w, h, 8.0)[..., :3], np.float32)
    tm = Tonemapper("pattanaik00")
    tm.process_frame(scene)
    frame_ms = _median_ms(lambda: tm.process_frame(scene, dt=1 / 30), a.reps)
    out = np.clip(tm.process_frame(scene, dt=1 / 30).output, 0, 1).astype(np.float32)
    spec_in = oiio.ImageSpec(w, h, 3, oiio.FLOAT)
    rows = []
    d = tempfile.mkdtemp(dir=os.path.dirname(os.path.abspath(out_file)))
    try:
        for ext, bits in FORMATS:
            path = os.path.join(d, f"frame{ext}")
            tmp = safeio.temp_path(path)
            spec = imagewrite.output_spec(spec_in, w, h, 3, ext, bits, "sRGB", {}, None, None,
                                        False, imageio.PNG_LEVEL, imageio.PNG_FILTER)

            def write():
                o = oiio.ImageOutput.create(tmp)
                assert o.open(tmp, spec) and o.write_image(out) and o.close()

            t_write = _median_ms(write, a.reps)
            t_verify = _median_ms(lambda: imagewrite.verify_written(tmp, path, None, w, h, 3),
                                  a.reps)

            def sync():
                safeio.fsync_path(tmp)
                os.replace(tmp, path)
                safeio.fsync_path(d, folder=True)
                os.replace(path, tmp)
            t_sync = _median_ms(sync, a.reps)
            safeio.remove(tmp)
            t_all = _median_ms(lambda: imagewrite.write_frame(path, out, spec_in, "sRGB", {}, bits),
                               a.reps)
            extra = t_verify + t_sync
            rows.append((ext[1:], bits, f"{t_write:.1f}", f"{t_verify:.1f}", f"{t_sync:.1f}",
                         f"{t_all:.1f}", f"{100 * extra / t_write:.0f}%",
                         f"{100 * extra / (frame_ms + t_all):.1f}%"))
    finally:
        for n in os.listdir(d):
            os.unlink(os.path.join(d, n))
        os.rmdir(d)
    import platform
    import subprocess
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, cwd=HERE).stdout.strip()
    except OSError:
        rev = "?"
    L = ["# Verified writes: what the read-back and the fsyncs cost", "",
         f"- {w}x{h}; host {platform.machine()}, {os.cpu_count()} CPUs; git {rev}; "
         f"command `python -m benchmarks.write_safety`",
         f"- a whole frame (pattanaik00, OpenCL, defaults): {frame_ms:.0f} ms median of {a.reps}",
         "- machines are noisy: compare the ratios", "",
         "| format | bits | encode + write ms | read back ms | fsync file + rename + fsync folder ms "
         "| write_frame ms (all) | (read back + fsync) / write | (read back + fsync) / (frame + write) |",
         "|---|---|---|---|---|---|---|---|"]
    L += ["| " + " | ".join(r) + " |" for r in rows]
    L += ["", "The read-back (`imagewrite.verify_written`) opens the file and checks its "
          "header, then that it is whole: PNG and JPEG end with their last chunk / marker "
          "(read from the file's end), TIFF's directory, written after the pixels, opened; "
          "EXR gives back its last row (one chunk). The fsyncs' cost depends on the disk and "
          "on what else is being written; on a network file system it is larger. File "
          f"system of the run: {fs_type(d)}."]
    with open(out_file, "w") as fh:
        fh.write("\n".join(L) + "\n")
    print("\n".join(L))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
