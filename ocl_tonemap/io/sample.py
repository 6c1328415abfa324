"""The built-in sample: the tunnel drive of Pattanaik 2000, Figure 7.

A car at 90 km/h drives on a sunlit road (~5000 cd/m^2), through an unlit
tunnel entrance into a tunnel whose road is ~5 cd/m^2 under sodium lamps, and
out into daylight again. Each frame is ray cast (2x2 supersampled) in
absolute cd/m^2, linear BT.709, and written as an OpenEXR sequence with
``whiteLuminance = 1`` and ``FramesPerSecond`` metadata.
"""

from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio

from ..models import lmsr
from ..models.lmsr import spectral_to_rgb
from ..models.photometry import Y_WEIGHTS
from .patterns import frame_path
from ..base.resources import available_memory, free_disk, gib

SPEED = 25.0                 # m/s (90 km/h)
CAM_H = 1.2                  # eye height, m
ROAD_HALF, WALL, CEIL = 3.5, 5.0, 5.5   # road half width, wall offset, ceiling height, m
MOUNTAIN = 40.0              # mountain face height above the road, m
L_ROAD_SUN, L_VERGE, L_ROCK, L_SKY = 5000.0, 2500.0, 3000.0, 8000.0
L_ROAD_TUNNEL, L_WALL, L_CEIL, L_LAMP = 5.0, 7.0, 2.0, 3000.0


def _colour(rgb):
    c = np.asarray(rgb, np.float64)
    return c / (c @ Y_WEIGHTS)   # unit luminance


C_ROAD, C_VERGE = _colour([1.0, 0.97, 0.9]), _colour([0.45, 1.0, 0.3])
C_ROCK, C_SKY = _colour([1.0, 0.9, 0.75]), _colour([0.65, 0.82, 1.25])
C_SODIUM = _colour([1.0, 0.55, 0.12])
C_TUNNEL = _colour([1.0, 0.8, 0.55])


def tunnel_layout(seconds: float) -> tuple[float, float]:
    """Tunnel entrance and exit (m along the road) for a drive of ``seconds``:
    30% approach, 40% inside, 30% after the exit."""
    total = SPEED * seconds
    return 0.3 * total, 0.7 * total


def render_frame(t: float, width: int, height: int, seconds: float, fov_deg: float = 60.0,
                 ss: int = 2) -> np.ndarray:
    """The view at time ``t`` s, (height, width, 3) float32 in cd/m^2."""
    z_in, z_out = tunnel_layout(seconds)
    z0 = SPEED * t
    tan = np.tan(np.radians(fov_deg) / 2.0)
    sx = (np.arange(width * ss) + 0.5) / (width * ss) * 2.0 - 1.0
    sy = 1.0 - (np.arange(height * ss) + 0.5) / (height * ss) * 2.0
    dx = (sx * tan)[None, :] * np.ones((height * ss, 1))
    dy = (sy * tan * height / width)[:, None] * np.ones((1, width * ss)) - 0.03  # slight downward gaze
    with np.errstate(divide="ignore", invalid="ignore"):
        t_road = np.where(dy < 0, CAM_H / -dy, np.inf)
        t_ceil = np.where(dy > 0, (CEIL - CAM_H) / dy, np.inf)
        t_wall = np.where(dx != 0, WALL / np.abs(dx), np.inf)
    L = np.empty(dx.shape)
    C = np.empty(dx.shape + (3,))

    def paint(mask, lum, col):
        L[mask] = lum if np.isscalar(lum) else lum[mask]
        C[mask] = col

    def outside(mask):
        road = mask & np.isfinite(t_road)
        xr = dx * t_road
        paint(road & (np.abs(xr) <= ROAD_HALF), L_ROAD_SUN, C_ROAD)
        paint(road & (np.abs(xr) > ROAD_HALF), L_VERGE, C_VERGE)
        paint(mask & ~road, L_SKY, C_SKY)

    def tunnel(mask, z_start):
        t_hit = np.minimum(np.minimum(t_road, t_ceil), t_wall)
        z_hit = z0 + t_hit
        beyond = mask & (z_hit >= z_out)
        outside(beyond)
        inner = mask & ~beyond
        is_road = inner & (t_hit == t_road)
        is_ceil = inner & (t_hit == t_ceil) & ~is_road
        is_wall = inner & ~is_road & ~is_ceil
        paint(is_road, L_ROAD_TUNNEL, C_TUNNEL)
        paint(is_wall, L_WALL, C_TUNNEL)
        lamp = is_ceil & (np.mod(z_hit, 12.0) < 1.2) & (np.abs(dx * t_hit) < 0.4)
        paint(is_ceil & ~lamp, L_CEIL, C_TUNNEL)
        paint(lamp, L_LAMP, C_SODIUM)

    everything = np.ones(dx.shape, bool)
    if z0 < z_in:
        t_face = z_in - z0
        xf, yf = dx * t_face, dy * t_face
        road_first = t_road < t_face
        outside(road_first)
        rest = ~road_first
        opening = rest & (np.abs(xf) < WALL) & (yf < CEIL - CAM_H)
        tunnel(opening, z_in)
        rock = rest & ~opening & (yf < MOUNTAIN - CAM_H)
        paint(rock, L_ROCK, C_ROCK)
        outside(rest & ~opening & ~rock)
    elif z0 < z_out:
        tunnel(everything, z0)
    else:
        outside(everything)
    img = L[..., None] * C
    img = img.reshape(height, ss, width, ss, 3).mean(axis=(1, 3))
    return img.astype(np.float32)


#: Bytes a frame's rendering holds per output pixel at its 2x2 supersampling (measured
#: with tracemalloc: 130 per sample, 4 samples; with room).
RENDER_BYTES_PER_PX = 4 * 160
#: Bytes a frame takes on disk per pixel at most (half RGB, before compression).
FILE_BYTES_PER_PX = 6


def plan_sample(out_dir: str, width: int, height: int, fps: float, seconds: float,
                flag_fps: str = "--fps") -> int:
    """The frames the sample will write, checked against this machine before anything
    is made: at least one, their files within the free disk under ``out_dir``, a
    frame's rendering within the memory available. Returns the frame count, or
    ValueError in one line naming the limit and the option that helps."""
    if os.path.lexists(out_dir) and not os.path.isdir(out_dir):
        raise ValueError(f"{out_dir}: is a file, not a folder; give a folder for the frames")
    n = int(round(seconds * fps))
    if n < 1:
        raise ValueError(f"--seconds {seconds:g} at {flag_fps} {fps:g} makes no frame: give "
                         f"at least {1.0 / fps:.3g} s")
    need = RENDER_BYTES_PER_PX * width * height
    have = available_memory()
    if need > have:
        raise ValueError(f"--size {width}x{height}: rendering a frame needs about {gib(need)} "
                         f"of memory and this machine has {gib(have)} available; give a "
                         f"smaller --size")
    where, free = free_disk(out_dir)
    if not os.access(where, os.W_OK | os.X_OK) or free == 0:
        raise ValueError(f"{out_dir}: cannot be written ({where} is read-only or full)")
    disk = float(FILE_BYTES_PER_PX) * width * height * n
    if disk > free:
        raise ValueError(f"{n} frames of {width}x{height} need up to {gib(disk)} and {where} "
                         f"has {gib(free)} free; give fewer --seconds, a lower {flag_fps} or "
                         f"a smaller --size")
    return n


def write_tunnel_sequence(out_dir: str, width: int = 320, height: int = 180, fps: float = 30.0,
                          seconds: float = 8.0, first_frame: int = 1,
                          name: str = "tunnel.####.exr") -> tuple[str, list[int]]:
    """Write the tunnel drive; returns (pattern path, frame numbers)."""
    os.makedirs(out_dir, exist_ok=True)
    n = int(round(seconds * fps))
    frames = list(range(first_frame, first_frame + n))
    pattern = os.path.join(out_dir, name)
    for i, f in enumerate(frames):
        img = render_frame(i / fps, width, height, seconds)
        spec = oiio.ImageSpec(width, height, 3, oiio.HALF)
        spec.attribute("whiteLuminance", 1.0)
        spec.attribute("FramesPerSecond", oiio.TypeDesc("rational"), (int(round(fps * 1000)), 1000))
        spec.attribute("oiio:ColorSpace", "lin_rec709")
        spec.attribute("compression", "zip")
        spec.attribute("ImageDescription", "ocl-tonemap built-in sample: tunnel drive (cd/m^2)")
        buf = oiio.ImageBuf(spec)
        buf.set_pixels(oiio.ROI(0, width, 0, height, 0, 1, 0, 3), img)
        path = frame_path(pattern, f)
        if not buf.write(path):
            raise RuntimeError(f"cannot write sample frame {path}: {buf.geterror()}")
    return pattern, frames


def spectral_patches(illuminant: str = "A", luminance: float = 1.0,
                     wavelengths=None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The 24 ColorChecker reflectances (Ohta, colour-science) under an illuminant,
    as spectral radiance (W sr^-1 m^-2 nm^-1) sampled at ``wavelengths`` (default
    400-700 nm every 10 nm), scaled so that the perfect white would have
    ``luminance`` cd/m^2. Returns (wavelengths, (24, N) spectra, patch names)."""
    colour = lmsr.colour_module()
    lam = np.arange(400.0, 701.0, 10.0) if wavelengths is None else np.asarray(wavelengths)
    il = colour.SDS_ILLUMINANTS[illuminant]
    E0 = np.interp(lam, il.wavelengths, il.values)
    cc = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    refl = np.array([np.interp(lam, sd.wavelengths, sd.values) for sd in cc.values()])
    white = lmsr.spectrum_weights(lam, lmsr.xyz_cmfs())[1] @ E0
    return lam, refl * E0 * (luminance / white), list(cc.keys())


def write_spectral_image(path: str, illuminant: str = "A", luminance: float = 1.0,
                         patch_px: int = 8, with_rgb: bool = False) -> np.ndarray:
    """A 6x4 ColorChecker as a spectral OpenEXR (channels ``S0.<wl>nm``, emissive
    radiance), optionally with RGB channels too. Returns the wavelengths."""
    lam, spectra, _ = spectral_patches(illuminant, luminance)
    cube = np.repeat(np.repeat(spectra.reshape(4, 6, -1), patch_px, 0), patch_px, 1)
    names = [f"S0.{w:g}nm" for w in lam]
    if with_rgb:
        cube = np.concatenate([spectral_to_rgb(lam, cube), cube], axis=2)
        names = ["R", "G", "B"] + names
    h, w, n = cube.shape
    spec = oiio.ImageSpec(w, h, n, oiio.FLOAT)
    spec.channelnames = tuple(names)
    spec.attribute("spectralLayoutVersion", "1.0")
    spec.attribute("emissiveUnits", "W.m^-2.sr^-1.nm^-1")
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, n), np.ascontiguousarray(cube, np.float32))
    if not buf.write(path):
        raise OSError(f"cannot write {path}: {buf.geterror()}")
    return lam
