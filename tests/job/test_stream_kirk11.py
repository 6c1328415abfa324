"""kirk11 on frames larger than the memory budget: shifted, filtered, composed and
written in row bands, each pass re-reading its rows from the file
(``backends/opencl/kirk11.py``: ``KirkSchedule._apply_banded``). Streamed runs
equal whole ones, in bounded memory."""

import json

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import main
from ocl_tonemap.pipeline import Tonemapper

from job.test_reliability import STREAM_SLACK_MB, _big, _exr, _peak_rss_mb

#: Streamed vs whole: the same kernels on the same pixels; only sums run in another
#: order: the frame's log-averages (levels, the anchor's output log-average) and
#: w_mean band by band in float64, the grid's splat band by band in float32. Measured:
#: 2e-7 relative at most (paper mode: identical); 1e-4 leaves room for devices whose
#: atomic adds into the grid come in another order.
TOL = dict(rtol=1e-4, atol=1e-6)
MODES = [["--bilateral", "exact"], ["--bilateral", "fast"],
         ["--mode", "paper", "--bilateral", "exact"], ["--mode", "paper", "--bilateral", "fast"]]


def _params(buf) -> dict:
    return json.loads(buf.spec().getattribute("ocltm:params"))


@pytest.mark.requires_opencl
@pytest.mark.parametrize("extra", MODES, ids=lambda e: "-".join(x.strip("-") for x in e))
def test_streamed_kirk11_equals_whole(tmp_path, extra):
    """301x203 RGBA EXR at --max-memory 8: bands of 43 rows (5 rows plus a 19-row halo
    each side for the exact filter); the same pixels, alpha and summary as whole."""
    src = _big(tmp_path / "big.exr", 301, 203, alpha=True)
    common = ["--operator", "kirk11", *extra, "-q", "--no-checkpoint", "--out-bits", "float"]
    assert main(["run", src, str(tmp_path / "w.exr"), *common]) == 0
    assert main(["run", src, str(tmp_path / "s.exr"), *common, "--max-memory", "8"]) == 0
    a, b = oiio.ImageBuf(str(tmp_path / "w.exr")), oiio.ImageBuf(str(tmp_path / "s.exr"))
    assert "row bands" in b.spec().getattribute("ocltm:streamed")
    assert a.spec().getattribute("ocltm:streamed") is None
    np.testing.assert_allclose(b.get_pixels(oiio.FLOAT), a.get_pixels(oiio.FLOAT), **TOL)
    pa, pb = _params(a), _params(b)                  # the summary, reduced over bands
    assert set(pa) == set(pb)
    for k, v in pa.items():
        if isinstance(v, float):
            assert pb[k] == pytest.approx(v, rel=1e-6, abs=1e-9), k
        else:
            assert pb[k] == v, k


@pytest.mark.slow
@pytest.mark.requires_opencl
def test_streamed_kirk11_bounds_memory(tmp_path):
    """A 2400x1600 frame (44 MiB as float32 RGB; ~1.3 GiB peak whole): streamed, no
    whole-frame plane is kept: it grows by under 3x the frame plus STREAM_SLACK_MB."""
    w, h = 2400, 1600
    src, small = _big(tmp_path / "big.exr", w, h), _big(tmp_path / "small.exr", 16, 16)
    frame_mb = w * h * 12 / 2**20
    common = ["--operator", "kirk11", "-q", "--no-checkpoint"]
    whole = _peak_rss_mb(["run", src, str(tmp_path / "w.png"), *common], small)
    streamed = _peak_rss_mb(["run", src, str(tmp_path / "s.png"), *common,
                             "--max-memory", "64"], small)
    assert streamed <= 3 * frame_mb + STREAM_SLACK_MB, (streamed, whole)
    assert streamed < whole


@pytest.mark.requires_opencl
def test_kirk11_flare_auto_streams_every_frame(tmp_path, caplog):
    """--flare auto: the measure pass leaves the frame's largest luminance for the
    flare check; a frame without light sources and one with a lamp (its flare in row
    bands, tests/effects/test_stream_effects.py) both stream and equal the whole renders."""
    import logging
    rng = np.random.default_rng(7)
    pix = (500.0 * rng.uniform(0.5, 2.0, (203, 301, 3))).astype(np.float32)
    plain = _exr(tmp_path / "plain.exr", pix, None, whiteLuminance=1.0)
    pix[100:104, 150:154] = 1e6                                  # a lamp
    lamp = _exr(tmp_path / "lamp.exr", pix, None, whiteLuminance=1.0)
    common = ["--operator", "kirk11", "--flare", "auto", "--no-checkpoint", "--out-bits",
              "float"]
    for src, flared in ((plain, False), (lamp, True)):
        w, s = str(tmp_path / "w.exr"), str(tmp_path / "s.exr")
        assert main(["run", src, w, *common, "-q"]) == 0
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="ocl_tonemap"):
            assert main(["run", src, s, *common, "--max-memory", "8"]) == 0
        b = oiio.ImageBuf(s)
        assert b.spec().getattribute("ocltm:streamed") is not None
        assert not any("not streamed" in r.getMessage() for r in caplog.records)
        ran = (b.spec().getattribute("ocltm:effects_ran") or "").split(",")
        assert ("flare" in ran) == flared
        np.testing.assert_allclose(b.get_pixels(oiio.FLOAT),
                                   oiio.ImageBuf(w).get_pixels(oiio.FLOAT), atol=1e-4, rtol=1e-4)


def _scene(h=90, w=130):
    rng = np.random.default_rng(3)
    lum = 10.0 ** rng.uniform(-3, 2, (h, w, 1))
    return (lum * rng.uniform(0.2, 1.0, (h, w, 3))).astype(np.float32)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("mode", ["default", "paper"])
@pytest.mark.parametrize("method", ["exact", "fast"])
def test_kirk11_beyond_one_band_equals_one_band(mode, method):
    """The API: a frame over ``max_band_pixels`` goes through the banded passes
    (three bands; the exact filter's halo rows re-read) and equals the one-band
    frame; so does ``process_stream`` from an array, whose summary is ready before
    the first band reaches the sink."""
    img = _scene()
    h, w, _ = img.shape
    opts = {"bilateral": method, "mode": mode}
    one = Tonemapper("kirk11", "opencl", options=opts, model="none")
    ref = one.process(img)
    tm = Tonemapper("kirk11", "opencl", options=opts, max_band_pixels=w * 40, model="none")
    assert len(tm.backend.bands(h, w)) > 1
    np.testing.assert_allclose(tm.process(img), ref, **TOL)
    for k, v in one.last.params.items():
        assert tm.last.params[k] == (pytest.approx(v, rel=1e-6) if isinstance(v, float) else v)

    st = Tonemapper("kirk11", "opencl", options=opts, max_band_pixels=w * 40, model="none")
    got, rows = np.zeros_like(ref), []

    def sink(y0, band):
        assert st.last.params["w_mean"] == pytest.approx(one.last.params["w_mean"], rel=1e-6)
        got[y0:y0 + len(band)] = band
        rows.append((y0, len(band)))
    st.process_stream(img, sink)
    assert len(rows) > 1 and rows[0][0] == 0                # in order, every row once
    assert all(y0 + n == y1 for (y0, n), (y1, _) in zip(rows, rows[1:]))
    assert rows[-1][0] + rows[-1][1] == h
    np.testing.assert_allclose(got, ref, **TOL)
