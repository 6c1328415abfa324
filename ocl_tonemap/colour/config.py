"""OCIO configs, input colourspaces and displays: which config, which colourspace a
file is in (the order below), which displays and views it offers.


Config resolution: ``--colorconfig`` > ``$OCIO`` > ``ocio://default``. The
bundled config is available by name (``ocl-tonemap`` or ``bundled``); any
``ocio://`` built-in URI and any file path work too. Never silently a raw
config: an unreadable config is an error.

Input colour (:func:`resolve_input`), first that applies:

1. ``--iscolorspace``;
2. the file's ``oiio:ColorSpace`` when the config knows it, else when OCIO's
   built-in config knows it (OIIO's colour interop IDs, ``lin_rec709_scene``...);
3. the EXR ``chromaticities`` attribute: a matrix to the working space
   (Bradford adaptation when the white is not D65, as OCIO's configs do);
4. a file rule of a config the user chose (a file, not an ``ocio://``
   built-in) when a rule other than the config's default rule matches;
5. otherwise scene-linear Rec.709, OIIO's and OpenEXR's convention for a file
   that says nothing -- reported once per run as an assumption.

The built-in configs' file rules (``*.exr -> ACES2065-1`` in ``ocio://default``)
are the ACES reference pipeline's convention, not knowledge about the file,
so they are not used. Pixels are converted to the working space, linear
BT.709/D65, where the papers' luminance formulas hold.

Output: the operators produce display-linear BT.709 light. Integer formats
get OCIO's display/view encoding (the config's un-tone-mapped view, so no
second tone curve); float outputs (EXR) default to display-linear light in
the config's linear colourspace with the display's primaries
(:meth:`ColourPipeline.linear_output`), tagged with it.
"""

from __future__ import annotations

import os
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import PyOpenColorIO as ocio

from ..models.photometry import RGB709_TO_XYZ
from ..base.resources import package_data_dir
from ..base.safeio import check_input

BUNDLED_NAMES = ("ocl-tonemap", "bundled")
WORKING_CANDIDATES = ("lin_rec709", "Linear Rec.709 (sRGB)", "Utility - Linear - sRGB",
                      "lin_srgb", "Linear BT.709")
#: Views that only encode (no tone curve), in order of preference.
PLAIN_VIEWS = ("Un-tone-mapped", "Video (colorimetric)", "Standard", "Display-linear")
USE_DISPLAY_NAME = "<USE_DISPLAY_NAME>"


class ColourError(ValueError):
    """A colour-management request that cannot be honoured."""


def bundled_config_path() -> Path:
    return package_data_dir("ocio_configs", "ocl_tonemap.ocio") / "ocl_tonemap.ocio"


def resolve_config_source(colorconfig: str | None = None) -> str:
    """Which config to load, as a path or ocio:// URI (see module doc)."""
    src = colorconfig or os.environ.get("OCIO") or "ocio://default"
    if src in BUNDLED_NAMES:
        return str(bundled_config_path())
    return src


def is_builtin_source(src: str) -> bool:
    """An ``ocio://`` built-in config (its file rules are not the user's)."""
    return str(src).startswith("ocio://")


#: Where each config loaded here came from (a file, an ``ocio://`` URI): errors name it.
_SOURCES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def remember_source(cfg: ocio.Config, src: str) -> ocio.Config:
    """Note that ``cfg`` was read from ``src`` (:func:`config_source` names it); returns it."""
    try:
        _SOURCES[cfg] = str(src)
    except TypeError:           # (an OCIO without weak references to its configs)
        pass
    return cfg


def config_source(cfg: ocio.Config) -> str:
    """What names ``cfg`` in an error: the file or URI it was loaded from, else its name
    and folder (a config a host made itself)."""
    try:
        src = _SOURCES.get(cfg)
    except TypeError:
        src = None
    if src:
        return src
    name = wd = ""
    try:
        name, wd = cfg.getName(), cfg.getWorkingDir()
    except Exception:  # noqa: BLE001 -- OCIO's own Exception: no more to say
        pass
    return ("the OCIO config" + (f" {name!r}" if name else "") + (f" in {wd}" if wd else ""))


def load_config(colorconfig: str | None = None) -> ocio.Config:
    src = resolve_config_source(colorconfig)
    if not is_builtin_source(src):
        # a FIFO (--colorconfig or $OCIO) is refused before OCIO opens it: its open
        # would wait inside the library, where no signal reaches
        check_input(src)
        if not os.path.exists(src):
            where = "--colorconfig" if colorconfig else "$OCIO"
            raise ColourError(f"cannot load OCIO config {src}: no such file ({where})")
    try:
        cfg = ocio.Config.CreateFromFile(src)
        cfg.validate()
    except Exception as exc:  # OCIO raises its own Exception type
        raise ColourError(f"cannot load OCIO config {src!r}: {exc}") from exc
    return remember_source(cfg, src)


def _has_cs(cfg: ocio.Config, name: str | None) -> bool:
    return bool(name) and cfg.getColorSpace(name) is not None


def working_space(cfg: ocio.Config) -> str:
    """The config's name for linear BT.709/D65."""
    for name in WORKING_CANDIDATES:
        cs = cfg.getColorSpace(name)
        if cs is not None:
            return cs.getName()
    raise ColourError("the OCIO config has no linear BT.709 colourspace (looked for "
                      + ", ".join(WORKING_CANDIDATES) + "); use the bundled config "
                      "(--colorconfig ocl-tonemap) or add one")


def input_colorspace(cfg: ocio.Config, path: str | None, file_cs: str | None,
                     override: str | None) -> tuple[str, str]:
    """(colourspace, why) by the precedence of the OCIO names only (override, file
    metadata, file rules, the scene_linear role); the CLI uses :func:`resolve_input`."""
    if override:
        if not _has_cs(cfg, override):
            raise ColourError(f"--iscolorspace {override!r} is not in the OCIO config")
        return cfg.getColorSpace(override).getName(), "--iscolorspace"
    if _has_cs(cfg, file_cs):
        return cfg.getColorSpace(file_cs).getName(), "file oiio:ColorSpace"
    if path and not cfg.filepathOnlyMatchesDefaultRule(path):
        cs = cfg.getColorSpaceFromFilepath(path)
        if isinstance(cs, tuple):        # OCIO >= 2.x Python: (name, rule index)
            cs = cs[0]
        return cs, "config file rules"
    role = cfg.getRoleColorSpace("scene_linear") if hasattr(cfg, "getRoleColorSpace") else None
    if not role:
        cs = cfg.getColorSpace("scene_linear")
        role = cs.getName() if cs is not None else None
    if not role:
        raise ColourError("no input colourspace: the file names none the config knows, "
                          "and the config has no scene_linear role; pass --iscolorspace")
    return role, "scene_linear role"


#: EXR/CIE chromaticities (rx, ry, gx, gy, bx, by, wx, wy) of the working space.
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
#: Bradford cone response matrix (Lam 1985), the CAT of OCIO's ACES configs.
BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367],
                     [0.0389, -0.0685, 1.0296]])


def chromaticities_to_xyz(chrom) -> np.ndarray:
    """RGB -> XYZ matrix (float64) of primaries and white given as xy chromaticities
    (white normalised to Y = 1), SMPTE RP 177."""
    c = [float(v) for v in chrom]
    if len(c) != 8 or not all(np.isfinite(c)):
        raise ColourError(f"chromaticities need 8 finite numbers (got {chrom!r})")
    xy = np.array(c).reshape(4, 2)
    if c[:6] == [1.0, 0.0, 0.0, 1.0, 0.0, 0.0] and xy[3, 1] > 0:
        return np.eye(3)          # the RGB is CIE XYZ (a Radiance XYZE picture); white E
    if np.any(xy[:3, 1] == 0) or xy[3, 1] <= 0:       # (AP0's blue primary has y < 0)
        raise ColourError(f"chromaticities with y = 0 or a white with y <= 0: {chrom!r}")
    XYZ = np.stack([xy[:, 0] / xy[:, 1], np.ones(4), (1.0 - xy.sum(axis=1)) / xy[:, 1]], axis=1)
    P = XYZ[:3].T
    if abs(np.linalg.det(P)) < 1e-9:
        raise ColourError(f"chromaticities have collinear primaries: {chrom!r}")
    return P * np.linalg.solve(P, XYZ[3])


def xyz_to_chromaticities(M: np.ndarray) -> tuple:
    """Inverse of :func:`chromaticities_to_xyz`: the xy of the columns and of their sum."""
    cols = [M[:, 0], M[:, 1], M[:, 2], M.sum(axis=1)]
    return tuple(float(v) for c in cols for v in (c[0] / c.sum(), c[1] / c.sum()))


def chromaticities_to_working(chrom) -> np.ndarray:
    """Matrix from RGB with these chromaticities to linear BT.709/D65, with a
    Bradford adaptation from the file's white to D65."""
    M = chromaticities_to_xyz(chrom)
    src_w = M.sum(axis=1)
    dst_w = RGB709_TO_XYZ.sum(axis=1)
    cat = np.linalg.inv(BRADFORD) @ np.diag((BRADFORD @ dst_w) / (BRADFORD @ src_w)) @ BRADFORD
    return np.linalg.inv(RGB709_TO_XYZ) @ cat @ M


def is_rec709(chrom, tol: float = 1e-3) -> bool:
    return bool(np.max(np.abs(np.asarray(chrom, np.float64) - REC709_CHROMATICITIES)) < tol)


@dataclass(frozen=True)
class InputColour:
    """How one input file's RGB becomes working-space RGB.

    kind : ``"ocio"`` (processor from ``colorspace`` of ``config``), ``"matrix"``
        (``matrix`` from the EXR chromaticities) or ``"working"`` (as it is).
    why : where the decision came from, for the log and the ``ocltm:`` metadata.
    assumed : nothing in the file or on the command line said it.
    """

    kind: str
    colorspace: str
    why: str
    assumed: bool = False
    matrix: tuple | None = None
    builtin: bool = False       # the name comes from OCIO's built-in config

    def describe(self) -> str:
        return f"{self.colorspace} ({self.why})"


_BUILTIN: dict = {}


def builtin_config() -> ocio.Config:
    """OCIO's built-in default config (knows OIIO's colour interop IDs)."""
    if "cfg" not in _BUILTIN:
        _BUILTIN["cfg"] = remember_source(ocio.Config.CreateFromFile("ocio://default"),
                                          "ocio://default")
    return _BUILTIN["cfg"]


def resolve_input(cfg: ocio.Config, path: str | None, file_cs: str | None,
                  override: str | None, chromaticities=None,
                  rules_from_user_config: bool = True,
                  chromaticities_from: str = "EXR chromaticities") -> InputColour:
    """The input colour of one file, by the precedence in the module doc
    (``chromaticities_from``: what the chromaticities are, for the record)."""
    work = working_space(cfg)
    if override:
        if not _has_cs(cfg, override):
            raise ColourError(f"--iscolorspace {override!r} is not in the OCIO config")
        return InputColour("ocio", cfg.getColorSpace(override).getName(), "--iscolorspace")
    unknown = ""
    if file_cs:
        if _has_cs(cfg, file_cs):
            return InputColour("ocio", cfg.getColorSpace(file_cs).getName(),
                               "file oiio:ColorSpace")
        b = builtin_config()
        if _has_cs(b, file_cs):
            return InputColour("ocio", b.getColorSpace(file_cs).getName(),
                               f"file oiio:ColorSpace {file_cs!r}, OCIO built-in config",
                               builtin=True)
        unknown = f"the file's oiio:ColorSpace {file_cs!r} is unknown; "
    if chromaticities is not None:
        try:
            if is_rec709(chromaticities):
                return InputColour("working", work, f"{unknown}{chromaticities_from}: Rec.709/D65")
            M = chromaticities_to_working(chromaticities)
        except ColourError as exc:
            unknown += f"ignored bad chromaticities ({exc}); "
        else:
            return InputColour("matrix", "RGB with chromaticities " + ",".join(
                f"{v:.4g}" for v in chromaticities), unknown + chromaticities_from,
                matrix=tuple(map(tuple, M)))
    if path and rules_from_user_config and not cfg.filepathOnlyMatchesDefaultRule(path):
        cs = cfg.getColorSpaceFromFilepath(path)
        if isinstance(cs, tuple):        # OCIO >= 2.x Python: (name, rule index)
            cs = cs[0]
        if _has_cs(cfg, cs):
            return InputColour("ocio", cfg.getColorSpace(cs).getName(), unknown + "config file rules")
    return InputColour("working", work, unknown + "untagged: scene-linear Rec.709, the "
                       "OIIO/OpenEXR convention; --iscolorspace to override", assumed=True)


def interop_id(cfg: ocio.Config, name: str) -> str | None:
    """The Color Interop Forum ID of the config's colourspace ``name``
    (``lin_p3d65_scene``, ``pq_rec2020_display`` ...): its own (OCIO 2.5 and later), else
    an alias of that form, else that of the colourspace of OCIO's built-in config that
    the name or an alias names (OCIO 2.1-2.4 configs carry none); None where unknown."""
    import re
    cs = cfg.getColorSpace(name) if name else None
    if cs is None:
        return None
    own = cs.getInteropID() if hasattr(cs, "getInteropID") else ""
    if own:
        return own.split(":")[-1]
    names = [cs.getName(), *(cs.getAliases() if hasattr(cs, "getAliases") else [])]
    for n in names:
        if re.fullmatch(r"[a-z0-9]+_[a-z0-9]+_(scene|display)", n):
            return n
    try:
        ref = builtin_config()
    except Exception:  # noqa: BLE001 -- no built-in config (an old OCIO): unknown
        return None
    if ref is cfg:
        return None
    for n in names:
        if ref.getColorSpace(n) is not None:
            return interop_id(ref, ref.getColorSpace(n).getName())
    return None


def default_display(cfg: ocio.Config) -> str:
    return cfg.getDefaultDisplay()


def default_view(cfg: ocio.Config, display: str) -> str:
    views = list(cfg.getViews(display))
    for v in PLAIN_VIEWS:
        if v in views:
            return v
    raise ColourError(f"display {display!r} has no un-tone-mapped view (looked for "
                      f"{', '.join(PLAIN_VIEWS)}); choose one with --view from: {', '.join(views)}")


def list_displays(cfg: ocio.Config) -> list[tuple[str, list[str]]]:
    return [(d, list(cfg.getViews(d))) for d in cfg.getDisplays()]


def apply_processor(cpu_proc, pixels: np.ndarray) -> None:
    """Apply an OCIO CPU processor to the RGB of a C-contiguous float32 array in place."""
    if pixels.dtype != np.float32 or not pixels.flags.c_contiguous:
        raise TypeError("OCIO processing needs C-contiguous float32 pixels")
    h, w, c = pixels.shape
    if c == 3:
        cpu_proc.applyRGB(pixels)
    elif c == 4:
        cpu_proc.applyRGBA(pixels)
    else:
        rgb = np.ascontiguousarray(pixels[..., :3])
        cpu_proc.applyRGB(rgb)
        pixels[..., :3] = rgb
