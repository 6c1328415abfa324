"""Where the effects meet one frame's data flow (``Tonemapper._run_frame``):

* **optical** effects change the light that reaches the eye, before it is metered:
  the flare (light scattered in the eye: its veil adapts the eye as the scene does,
  Ward Larson et al. 1997, CIE's veiling luminance L_seq added to the background)
  and the scene plugins. Their strength may not depend on the observer's state (a
  shot's measure pass knows none): the flare's sources are those of an observer
  adapted to the frame, its weight the mechanism plan's;
* **seen** effects change what the observer makes of that light, after its state
  step, their strength part of the state: the Purkinje shift (rods joining the
  cone pathways) and chromatic adaptation's gains where the schedule cannot put
  them on the cone signals. The metering sees the light, not them.

docs/models.md, "Effects before and after the metering".
"""

from __future__ import annotations

import numpy as np

from ..operators.base import Frame


def metered_weight(fx, max_Y: float | None, lim: float) -> float | None:
    """The flare's weight in the frame that is metered (the plan's: ramps and
    hysteresis included), None where no pixel can be a source (then no weight
    changes the frame): what a shot's integrate pass checks its statistics by."""
    if fx.settings.flare == "off" or not (max_Y is None or max_Y > lim):
        return None
    return float(fx.weight("flare")) if fx.s.flare != "off" else 0.0


def optical_effects(fx, frame: Frame, levels, lim: float, eff: dict, primaries):
    """The flare and the scene plugins on the working frame ``levels.rgb`` (cd/m^2):
    (the frame to meter and map, the one given where nothing changed it; the flare's
    :func:`metered_weight`). ``fx``: the run's ``Effects``; ``lim``: the flare's source
    limit; ``eff``: the frame's effect records."""
    G_rod, G_cone = levels.goal
    plugins = fx.slot_plugins("scene")
    weight = metered_weight(fx, levels.max_Y, lim)
    rgb, changed = levels.rgb, False
    new, eff["flare"] = fx.flare(rgb, G_rod, G_cone, lim)
    if new is not None:
        rgb, changed = new, True
    if plugins and not isinstance(rgb, np.ndarray):
        rgb = np.asarray(rgb)             # the stages below work on host pixels
    for plugin in plugins:
        new, eff[plugin.NAME] = plugin.run(rgb, {"G_rod": G_rod, "G_cone": G_cone})
        if new is not None:
            rgb, changed = np.asarray(new, np.float32), True
    return (changed_frame(frame, rgb, primaries) if changed else frame), weight


def seen_effects(fx, metered: Frame, frame: Frame, levels, eff: dict, own_chroma: bool,
                 primaries) -> Frame:
    """The Purkinje shift and chromatic gains on the scene (``own_chroma``: the
    schedule has no receptor gains) after the state step, on the metered frame
    (``frame``: the one given, whose working pixels are ``levels.rgb`` where nothing
    changed it before the metering). The frame to map."""
    ca = eff.get("chromatic_adaptation") or {}
    gains = ca.get("gains") if (own_chroma and ca.get("ran")) else None
    if not eff["purkinje"].get("ran") and gains is None:
        return metered
    rgb = levels.rgb if metered is frame else metered.pixels
    if isinstance(rgb, np.ndarray):
        rgb = rgb[..., :3]
    if eff["purkinje"].get("ran"):
        rgb, eff["purkinje"] = fx.purkinje_shift(rgb, eff["purkinje"])
    if gains is not None:
        rgb = (np.asarray(rgb) * np.asarray(gains, np.float32)).astype(np.float32)
    return changed_frame(metered, rgb, primaries)


def changed_frame(frame: Frame, rgb, primaries) -> Frame:
    """A new frame of working ``rgb`` (cd/m^2, scale 1; a host array or a device image,
    RGB only), with ``frame``'s alpha."""
    pix = frame.pixels
    if isinstance(rgb, np.ndarray):
        rgb = np.asarray(rgb, np.float32)[..., :3]
        if pix.shape[2] == 4:
            rgb = np.concatenate([rgb, np.asarray(pix[..., 3:4], np.float32)], axis=2)
        rgb = np.ascontiguousarray(rgb, np.float32)
    return Frame(rgb, 1.0, None, primaries)
