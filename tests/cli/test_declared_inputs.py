"""Every declared number of every sub-command, at the values that break tools: NaN,
+-Inf, 0, -1, its bounds, just past them and 1e300 (issue 58). Each value is either
refused in one line naming the flag (exit 2), or accepted, and then the command runs
to finite output: ``run`` and ``simulate`` on a tiny image, ``visibility`` (its JSON
finite where the declaration does not allow infinity), ``sample``/``demo`` where the
frames they would make are few (else their plan, checked before anything is made).
The shot passes' own flags are parsed (a Dask cluster or a store per value would be a
benchmark, not a test); their run options are run's."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import COMMANDS, build_parser, main
from ocl_tonemap.base.quantities import Numbers, Quantity, Text


def _declared_actions():
    """(command, flag, declaration, action) of every declared option of every
    sub-command, the run options once (under run)."""
    p = build_parser()
    sub = next(a for a in p._actions if a.__class__.__name__ == "_SubParsersAction")
    out, seen = [], set()
    for c in COMMANDS:
        for a in sub.choices[c.name]._actions:
            d = getattr(a.type, "declared", None)
            if d is None or not a.option_strings:
                continue
            flag = a.option_strings[-1]
            key = flag if c.runs else (c.name, flag)
            if key in seen:
                continue
            seen.add(key)
            out.append((c.name, flag, d, a))
    return out


ACTIONS = _declared_actions()


def _text(x) -> str:
    if isinstance(x, float) and math.isfinite(x) and x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return repr(x) if isinstance(x, float) else str(x)


def _edges(q: Quantity) -> list[str]:
    """The values that break tools, for one number."""
    vals = [math.nan, math.inf, -math.inf, 0.0, -1.0, 1e300]
    for b in (q.lo, q.hi):
        if math.isfinite(b):
            step = 1.0 if q.integer else max(abs(b) * 1e-6, 1e-9)
            vals += [b, b - step if b == q.lo else b + step]     # the bound, just past
    return sorted({_text(v) for v in vals})


def _typical(q: Quantity) -> str:
    lo = q.lo if math.isfinite(q.lo) else -1.0
    hi = q.hi if math.isfinite(q.hi) else lo + 2.0
    lo = max(lo, q.data[0]) if q.data else lo
    hi = min(hi, q.data[1]) if q.data and math.isfinite(q.data[1]) else hi
    x = lo + 0.25 * (hi - lo) if hi - lo < 100 else math.sqrt(max(lo, 1e-6) * hi)
    return str(int(math.ceil(x))) if q.integer else f"{x:.6g}"


def _values(d) -> list[str]:
    if isinstance(d, Quantity):
        return _edges(d)
    if isinstance(d, Numbers):
        places = list(d.parts) or [d.each]
        base = [_typical(q) for q in places]
        out = []
        for i, q in enumerate(places):
            for v in _edges(q):
                out.append(",".join(base[:i] + [v] + base[i + 1:]))
        return out
    assert isinstance(d, Text)
    return ["nan", "inf", "-inf", "0", "-1", "1e300", "", "x"]


CASES = [(c, f, v) for c, f, d, _ in ACTIONS for v in _values(d)]


def test_every_declared_option_is_covered():
    """The declarations reach every sub-command that takes numbers: run's, the
    operators' and effects', the calculator's, the sample's, the shot passes'."""
    flags = {f for _, f, _, _ in ACTIONS}
    for f in ("--fps", "--exposure", "--preadapt", "--display-black", "--blue-shift",
              "--shift-scale", "--local-strength", "--sigma-spatial", "--lut", "--fov",
              "--age", "--flare-threshold", "--illuminant", "--ocio-export-size",
              "--target-size", "--k", "--background", "--after", "--pixel", "--at",
              "--seconds", "--size", "--workers", "--chunk-frames", "--keyframe-every",
              "--threads", "--max-memory", "--checkpoint-every", "--frames"):
        assert f in flags, f
    assert len(CASES) > 300


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """An 8 x 6 still in cd/m^2 (a dim and a bright half)."""
    d = tmp_path_factory.mktemp("declared")
    img = np.full((6, 8, 3), 20.0, np.float32)
    img[:, 4:] = 2000.0
    spec = oiio.ImageSpec(8, 6, 3, oiio.FLOAT)
    spec.attribute("whiteLuminance", 1.0)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, 8, 0, 6, 0, 1, 0, 3), img)
    assert buf.write(str(d / "in.exr"))
    return d


def _context(cmd: str, flag: str) -> list[str]:
    """What the flag needs beside it to take effect: its operator, its effect on."""
    from ocl_tonemap.cli.options import operator_flags
    from ocl_tonemap.effects.settings import options
    for o, ops in operator_flags():
        if o.flag == flag:
            return ["--operator", ops[0]]
    for k, (o, owners) in options().items():
        if o.flag == flag and owners and k not in owners:
            return ["--" + owners[0].replace("_", "-"), "on"]
    if flag in ("--target-size", "--observation-time"):
        return ["--visibility", "{d}-vis.exr"]
    if flag == "--ocio-export-size":
        return ["--ocio-export", "{d}-export"]
    if flag == "--plot-frames":
        return ["--plot", "{d}-plot.png"]
    return []


def _argv(cmd: str, flag: str, value: str, d, n: int) -> list[str]:
    out = str(d / f"o{n}.exr")
    ctx = [a.replace("{d}", str(d / f"x{n}")) for a in _context(cmd, flag)]
    given = [f"{flag}={value}"]
    if cmd == "run":
        return ["run", str(d / "in.exr"), out, "-q", "--luminance-scale", "1", *ctx, *given]
    if cmd == "simulate":
        pre = [] if flag == "--preadapt" else ["--preadapt", "1000:60"]
        at = [] if flag == "--at" else ["--at", "1,10"]
        return ["simulate", str(d / "in.exr"), str(d / f"o{n}.####.exr"), "-q",
                "--luminance-scale", "1", *pre, *at, *given]
    if cmd == "visibility":
        base = [] if flag == "--background" else ["--background", "10"]
        step = ["--adapted-to", "100"] if flag in ("--after", "--for") else []
        return ["visibility", "--json", *base, *step, *given]
    if cmd in ("sample", "demo"):
        size = [] if flag == "--size" else ["--size", "4x3"]
        return [cmd, str(d / f"s{n}"), "-q", *size, *given]
    return [cmd, str(d / "in.####.exr"), str(d / f"o{n}.####.exr"), *given]


def _one_line_naming(err: str, flag: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    errors = [ln for ln in lines if "ERROR" in ln]
    assert len(errors) == 1, err
    assert flag in errors[0], err
    assert "Traceback" not in err


def _finite_json(v, allow_inf: bool) -> bool:
    if isinstance(v, dict):
        return all(_finite_json(x, allow_inf) for x in v.values())
    if isinstance(v, list):
        return all(_finite_json(x, allow_inf) for x in v)
    if isinstance(v, float):
        return math.isfinite(v)
    if isinstance(v, str):
        return allow_inf or v not in ("inf", "-inf", "nan")
    return True


@pytest.mark.parametrize("cmd,flag,value", CASES,
                         ids=[f"{c}{f}={v}" for c, f, v in CASES])
def test_declared_value_is_refused_in_one_line_or_runs_finite(cmd, flag, value, tiny, capsys):
    n = CASES.index((cmd, flag, value))
    argv = _argv(cmd, flag, value, tiny, n)
    parser = build_parser(cmd)
    try:
        a = parser.parse_args(argv)
    except SystemExit as e:
        assert e.code == 2
        _one_line_naming(capsys.readouterr().err, flag)
        return
    capsys.readouterr()
    if cmd in ("sample", "demo"):
        from ocl_tonemap.io.sample import plan_sample
        fps = a.fps if cmd == "sample" else 30.0
        try:
            frames = plan_sample(a.outdir, *a.size, fps, a.seconds)
        except ValueError as e:
            assert flag in str(e) or "--size" in str(e) or "--seconds" in str(e)
            assert not os.path.exists(a.outdir)          # nothing made before the plan
            return
        if frames > 8 or a.size[0] * a.size[1] > 64 * 64:
            return                        # accepted; making them is a benchmark's work
    elif cmd not in ("run", "simulate", "visibility"):
        return                            # the passes: parsed (see the module's docstring)
    try:
        rc = main(argv)
    except SystemExit as e:
        rc = e.code
    cap = capsys.readouterr()
    if rc != 0:
        assert rc == 2, cap.err
        _one_line_naming(cap.err, flag if flag != "--display-white" else "--display")
        return
    if cmd == "visibility":
        doc = json.loads(cap.out)
        assert _finite_json(doc, allow_inf=flag == "--time"), cap.out
        return
    if cmd in ("sample", "demo"):
        return
    outs = [os.path.join(tiny, f) for f in os.listdir(tiny) if f.startswith(f"o{n}")
            and f.endswith(".exr")]
    assert outs, cap.err
    for o in outs:
        px = oiio.ImageBuf(o).get_pixels(oiio.FLOAT)
        assert np.isfinite(px).all(), o
