"""Real HDR photographs for the appearance benchmark, fetched from PyPI.

The wheel of ``viser==0.2.23`` ships ten Poly Haven HDRIs (CC0, 1024x512
Radiance .hdr, linear Rec.709, *relative* radiance) at
``viser/client/public/hdri/*.hdr``. :func:`fetch_photos` downloads the wheel
once with pip, extracts only those .hdr files into a cache folder and returns
their paths; later calls find them there and download nothing. :func:`load_photo`
reads one at the size a benchmark needs.

Cache folder: ``$OCLTM_PHOTOS``, else ``~/.cache/ocl-tonemap/photos/``.

One command (fetch and list):  python -m benchmarks.lib.photos [--cache DIR]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

WHEEL = "viser==0.2.23"
HDRI_PREFIX = "viser/client/public/hdri/"

#: The photographs the benchmark uses: name -> (what it shows, natural level cd/m^2).
#: The natural level is the log-average luminance a person would meet there
#: (README "Calibration and colour": night 0.01, dusk 1, interior 30, daylight 5000).
PHOTOS = {
    "rooitou_park_1k": ("daylight, sun", 5000.0),
    "st_fagans_interior_1k": ("interior", 30.0),
    "lebombo_1k": ("interior with window", 30.0),
    "kiara_1_dawn_1k": ("dawn/dusk", 1.0),
    "venice_sunset_1k": ("sunset", 10.0),
    "dikhololo_night_1k": ("night", 0.01),
}


class PhotoFetchError(RuntimeError):
    """The photographs could not be fetched (message says why and what to do)."""


def default_cache_dir() -> Path:
    env = os.environ.get("OCLTM_PHOTOS")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "ocl-tonemap" / "photos"


def _is_radiance(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            head = f.read(10)
    except OSError:
        return False
    return head.startswith(b"#?RADIANCE") or head.startswith(b"#?RGBE")


def cached_photos(cache_dir: str | os.PathLike | None = None) -> list[Path]:
    """The .hdr files already in the cache folder (sorted; maybe empty)."""
    d = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    if not d.is_dir():
        return []
    return sorted(p for p in d.glob("*.hdr") if _is_radiance(p))


def fetch_photos(cache_dir: str | os.PathLike | None = None, names=None,
                 timeout_s: float = 900.0) -> list[Path]:
    """Paths of the HDR photographs, downloading the viser wheel when needed.

    ``cache_dir``: where the .hdr files live (default :func:`default_cache_dir`).
    ``names``: stems that must be present (default: those of :data:`PHOTOS`);
    the download is skipped when they all are. Extracts every .hdr of the wheel
    (ten files, ~16 MB). Raises :class:`PhotoFetchError` with a readable message
    when pip cannot download the wheel or the wheel lacks the files.
    """
    d = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    want = list(names) if names is not None else list(PHOTOS)
    have = {p.stem: p for p in cached_photos(d)}
    if all(n in have for n in want):
        return sorted(have.values())
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise PhotoFetchError(f"cannot create the photo cache {d}: {e}; set $OCLTM_PHOTOS "
                              "to a writable folder") from None
    with tempfile.TemporaryDirectory(prefix="ocltm-photos-") as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
               "--disable-pip-version-check", "-d", tmp, WHEEL]
        print(f"photos: downloading {WHEEL} (about 29 MB) for its HDR photographs ...",
              file=sys.stderr)
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise PhotoFetchError(f"pip download of {WHEEL} took over {timeout_s:.0f} s; "
                                  "check the network / PyPI index settings") from None
        except OSError as e:
            raise PhotoFetchError(f"cannot run pip ({e})") from None
        if r.returncode != 0:
            tail = "\n".join((r.stderr or r.stdout or "").strip().splitlines()[-6:])
            raise PhotoFetchError(
                f"pip could not download {WHEEL} (exit status {r.returncode}):\n{tail}\n"
                f"Needs access to PyPI (or a pip index/mirror that has {WHEEL}). Alternatively "
                f"put the Poly Haven .hdr files ({', '.join(want)}) into {d} "
                "(or point $OCLTM_PHOTOS at a folder that has them).")
        wheels = sorted(Path(tmp).glob("viser-*.whl"))
        if not wheels:
            raise PhotoFetchError(f"pip reported success but left no viser wheel in {tmp}")
        try:
            with zipfile.ZipFile(wheels[0]) as z:
                members = [m for m in z.namelist()
                           if m.startswith(HDRI_PREFIX) and m.lower().endswith(".hdr")]
                if not members:
                    raise PhotoFetchError(f"{wheels[0].name} holds no {HDRI_PREFIX}*.hdr files")
                for m in members:
                    target = d / Path(m).name
                    part = target.with_suffix(".hdr.part")
                    with z.open(m) as src, open(part, "wb") as dst:
                        while True:
                            chunk = src.read(1 << 20)
                            if not chunk:
                                break
                            dst.write(chunk)
                    os.replace(part, target)
        except zipfile.BadZipFile as e:
            raise PhotoFetchError(f"the downloaded wheel {wheels[0].name} is not a zip ({e})") \
                from None
    have = {p.stem: p for p in cached_photos(d)}
    missing = [n for n in want if n not in have]
    if missing:
        raise PhotoFetchError(f"{WHEEL} lacks the photographs {', '.join(missing)}")
    print(f"photos: {len(have)} .hdr files in {d}", file=sys.stderr)
    return sorted(have.values())


def load_photo(path, w: int, h: int | None = None) -> np.ndarray:
    """A photograph ``w`` pixels wide: (h, w, 3) float32, relative radiance, finite, >= 0.

    ``h`` None: the whole picture, its aspect kept; resized with a box (area) filter
    where ``w`` is not its width, else left as read. ``h`` given: centre-cropped to
    w:h and resized, box filter down, triangle up. Never a windowed sinc: it rings
    around the sun (negative lobes of -3000 next to 60 000) and would paint black
    halos into the scene.
    """
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise RuntimeError(f"cannot read {path}: {buf.geterror()}")
    spec = buf.spec()
    if h is None:
        h = max(1, int(round(spec.height * w / spec.width)))
        if w != spec.width:
            buf = oiio.ImageBufAlgo.resize(buf, filtername="box",
                                           roi=oiio.ROI(0, w, 0, h, 0, 1, 0, spec.nchannels))
    else:
        ch, cw = spec.height, int(round(spec.height * w / h))
        if cw > spec.width:
            cw, ch = spec.width, int(round(spec.width * h / w))
        x0, y0 = (spec.width - cw) // 2, (spec.height - ch) // 2
        buf = oiio.ImageBufAlgo.cut(buf, oiio.ROI(x0, x0 + cw, y0, y0 + ch, 0, 1, 0, 3))
        buf = oiio.ImageBufAlgo.resize(buf, filtername="box" if w <= cw else "triangle",
                                       roi=oiio.ROI(0, w, 0, h, 0, 1, 0, 3))
    px = np.asarray(buf.get_pixels(oiio.FLOAT), np.float32)[..., :3]
    return np.ascontiguousarray(np.maximum(np.nan_to_num(px, nan=0.0, posinf=0.0, neginf=0.0),
                                           0.0))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", help="cache folder (default $OCLTM_PHOTOS or "
                    "~/.cache/ocl-tonemap/photos)")
    a = ap.parse_args(argv)
    try:
        paths = fetch_photos(a.cache)
    except PhotoFetchError as e:
        print(f"photos ERROR: {e}", file=sys.stderr)
        return 2
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
