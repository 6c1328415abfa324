"""Colour management through OpenColorIO.

Config resolution: ``--colorconfig`` > ``$OCIO`` > ``ocio://default``. The
bundled config is available by name (``ocl-tonemap`` or ``bundled``); any
``ocio://`` built-in URI and any file path work too. Never silently a raw
config: an unreadable config is an error.

Input colourspace: ``--iscolorspace`` > the file's ``oiio:ColorSpace`` (when
the config knows it) > a non-default file rule of the config > the
``scene_linear`` role. Pixels are converted to the working space, linear
BT.709/D65, where the papers' luminance formulas hold.

Output: the operators produce display-linear BT.709 light, which OCIO encodes
with a display/view. The default view is the config's un-tone-mapped one, so
no second scene tone curve is applied on top of the operator.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import PyOpenColorIO as ocio

BUNDLED_NAMES = ("ocl-tonemap", "bundled")
WORKING_CANDIDATES = ("lin_rec709", "Linear Rec.709 (sRGB)", "Utility - Linear - sRGB",
                      "lin_srgb", "Linear BT.709")
#: Views that only encode (no tone curve), in order of preference.
PLAIN_VIEWS = ("Un-tone-mapped", "Video (colorimetric)", "Standard", "Display-linear")
USE_DISPLAY_NAME = "<USE_DISPLAY_NAME>"


class ColourError(ValueError):
    """A colour-management request that cannot be honoured."""


def bundled_config_path() -> Path:
    from .runtime import package_data_dir
    return package_data_dir("ocio_configs", "ocl_tonemap.ocio") / "ocl_tonemap.ocio"


def resolve_config_source(colorconfig: str | None = None) -> str:
    """Which config to load, as a path or ocio:// URI (see module doc)."""
    src = colorconfig or os.environ.get("OCIO") or "ocio://default"
    if src in BUNDLED_NAMES:
        return str(bundled_config_path())
    return src


def load_config(colorconfig: str | None = None) -> ocio.Config:
    src = resolve_config_source(colorconfig)
    try:
        cfg = ocio.Config.CreateFromFile(src)
        cfg.validate()
    except Exception as exc:  # OCIO raises its own Exception type
        raise ColourError(f"cannot load OCIO config {src!r}: {exc}") from exc
    return cfg


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
    """(colourspace, why) for an input file, by the documented precedence."""
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


class ColourPipeline:
    """OCIO processors for one run: input -> working, working -> display."""

    def __init__(self, cfg: ocio.Config, display: str | None = None, view: str | None = None):
        self.cfg = cfg
        self.working = working_space(cfg)
        displays = list(cfg.getDisplays())
        self.display = display or default_display(cfg)
        if self.display not in displays:
            raise ColourError(f"display {self.display!r} not in the OCIO config; "
                              f"available: {', '.join(displays)}")
        self.view = view or default_view(cfg, self.display)
        if self.view not in list(cfg.getViews(self.display)):
            raise ColourError(f"view {self.view!r} not in display {self.display!r}; available: "
                              + ", ".join(cfg.getViews(self.display)))
        self._in_procs: dict[str, object] = {}
        proc = cfg.getProcessor(self.working, self.display, self.view, ocio.TRANSFORM_DIR_FORWARD)
        self._out = proc.getDefaultCPUProcessor()

    @property
    def output_colorspace(self) -> str:
        name = self.cfg.getDisplayViewColorSpaceName(self.display, self.view)
        return self.display if (not name or name == USE_DISPLAY_NAME) else name

    @property
    def view_is_plain(self) -> bool:
        return self.view in PLAIN_VIEWS or self.view.lower() == "raw"

    def to_working(self, pixels: np.ndarray, src_cs: str) -> np.ndarray:
        """Convert (H, W, C>=3) float32 pixels from ``src_cs`` in place; returns them."""
        if self.cfg.getColorSpace(src_cs).getName() == self.working:
            return pixels
        proc = self._in_procs.get(src_cs)
        if proc is None:
            proc = self.cfg.getProcessor(src_cs, self.working).getDefaultCPUProcessor()
            self._in_procs[src_cs] = proc
        _apply(proc, pixels)
        return pixels

    def display_primaries(self) -> np.ndarray:
        """(3, 3): column c is the working-space linear RGB of the display's primary c
        (through the inverse display/view transform), scaled so that the columns
        sum to luminance 1. For a BT.709 display this is the identity."""
        proc = self.cfg.getProcessor(self.working, self.display, self.view,
                                     ocio.TRANSFORM_DIR_INVERSE).getDefaultCPUProcessor()
        codes = np.array([[[0.5, 0, 0], [0, 0.5, 0], [0, 0, 0.5], [0, 0, 0]]], np.float32)
        _apply(proc, codes)
        D = (codes[0, :3] - codes[0, 3]).T.astype(np.float64)
        from .photometry import Y_WEIGHTS
        y = float(Y_WEIGHTS @ D.sum(axis=1))
        if not (np.all(np.isfinite(D)) and y > 0):
            return np.eye(3)
        return D / y

    def encode(self, display_linear: np.ndarray) -> np.ndarray:
        """Display-linear working-space RGB -> display encoding (new array)."""
        out = np.array(display_linear, dtype=np.float32, copy=True, order="C")
        _apply(self._out, out)
        return out


def _apply(cpu_proc, pixels: np.ndarray) -> None:
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
