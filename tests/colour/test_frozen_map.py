"""The last frame's per-pixel mapping, frozen (``Tonemapper.last_mapping`` and
``colour/export.frozen_raw``), what an OCIO export samples: the smooth raw map
clamped at 0 and put through the shoulder is the frame's own output, and sampling it
moves no state."""

import numpy as np
import pytest

from ocl_tonemap.colour.export import frozen_raw, frozen_shoulder
from ocl_tonemap.effects import EffectSettings
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.io.sample import render_frame


@pytest.mark.parametrize("op", ["pattanaik00", "durand00"])
@pytest.mark.parametrize("per_pixel", [False, True])
def test_raw_clamped_and_shouldered_is_the_frame(op, per_pixel):
    """With the per-pixel effects on too (chromatic adaptation, the Purkinje shift of a
    night frame)."""
    fx = EffectSettings(chromatic_adaptation="on", purkinje="on") if per_pixel else None
    tm = Tonemapper(op, model="none", backend="reference", effects=fx)
    for k, (t, level) in enumerate(((0.0, 1.0), (4.0, 1.0), (7.0, 1e-4))):
        img = np.ascontiguousarray(render_frame(t, 64, 36, 8.0)[..., :3], np.float32) * level
        r = tm.process_frame(img, dt=None if k == 0 else 0.5)
        state = tm.state.to_json()
        o, p, g = tm.last_mapping()
        raw = frozen_raw(o, p, g, r.info.effects.get("purkinje"))
        x = img.reshape(-1, 3).astype(np.float64)
        again = frozen_shoulder(p)(np.maximum(raw(x), 0.0)).reshape(r.output.shape)
        np.testing.assert_allclose(again, r.output, rtol=2e-6, atol=2e-7)
        assert not per_pixel or k < 2 or r.info.effects["purkinje"]["ran"]
        raw(np.full((5, 3), 1e6))
        assert tm.state.to_json() == state


def test_raw_crosses_zero_where_the_chroma_scale_clamps():
    """pattanaik00's default colour in daylight boosts chroma (c > 1): a saturated
    channel goes below zero in the raw map (the output clamps it to 0) and the raw
    map is continuous through that point, not clamped."""
    tm = Tonemapper("pattanaik00", model="none", backend="reference")
    tm.process_frame(np.full((4, 4, 3), 5000.0, np.float32))
    o, p, g = tm.last_mapping()
    assert p.chroma > 1.0
    raw = frozen_raw(o, p, g, None)
    b = np.linspace(0.0, 3000.0, 301)
    rgb = np.stack([np.full_like(b, 5000.0), np.full_like(b, 4000.0), b], -1)
    out = raw(rgb)[:, 2]
    assert out.min() < 0 < out.max()
    assert np.all(np.diff(out) > 0)                  # monotone through the crossing
    assert np.max(np.abs(np.diff(out, 2))) < 0.05 * np.max(np.abs(np.diff(out)))


def test_last_mapping_before_any_frame_is_an_error():
    with pytest.raises(ValueError, match="no frame"):
        Tonemapper("pattanaik00", model="none", backend="reference").last_mapping()
