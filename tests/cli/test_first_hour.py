"""What a new user saw in the first hour (issue 67, items 7-13), as they see it: the
help of every sub-command, the errors, the listings, the names of the files written,
the plot and the calculator, each through the real command line."""

import json
import os
import re
import subprocess
import sys

import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import COMMANDS, main
from ocl_tonemap.io.patterns import frame_path


def _help(capsys, *argv) -> str:
    with pytest.raises(SystemExit) as e:
        main([*argv, "--help"])
    assert e.value.code == 0
    return capsys.readouterr().out


def _group_titles(text: str) -> list[str]:
    """The option groups of a help, in its order (a line at the margin ending in ':')."""
    return [ln[:-1] for ln in text.splitlines()
            if ln.endswith(":") and not ln.startswith(" ") and not ln.startswith("usage")]


# -- 7: the help -----------------------------------------------------------------------------
def test_run_help_is_in_a_users_reading_order(capsys):
    """Inputs and calibration, the operator (its own options with it), effects, outputs,
    time and state, visibility, and a shot on many machines last."""
    titles = _group_titles(_help(capsys, "run"))
    assert titles[:2] == ["positional arguments", "options"]

    def at(prefix):
        hits = [k for k, t in enumerate(titles) if t.startswith(prefix)]
        assert len(hits) == 1, (prefix, titles)
        return hits[0]

    order = [at(p) for p in ("input", "calibration", "operator and observer",
                             "mechanisms and effects", "display", "output",
                             "time and state", "visibility", "a shot on many machines")]
    assert order == sorted(order), titles
    assert order[-1] == len(titles) - 1, titles                 # the shot last
    own = [k for k, t in enumerate(titles) if t.endswith(" options") and t != "options"]
    assert own and all(at("operator and observer") < k < at("mechanisms and effects")
                       for k in own), titles      # each operator's options by the operator
    # the visibility's flags are in its group, not the outputs'
    text = _help(capsys, "run")
    vis = text.split("\nvisibility")[1].split("\n\n")[0]
    for flag in ("--visibility OUT", "--visibility-view", "--target X,Y,SIZE",
                 "--observation-time", "--adrian", "--veil-halo"):
        assert flag in vis, flag


@pytest.mark.parametrize("cmd", [c.name for c in COMMANDS])
def test_every_sub_commands_help_opens_with_what_it_does(cmd, capsys, monkeypatch):
    """The first line after the usage says what the command does: its summary (the one
    the top-level help lists), whole, on one line of an 80-column terminal."""
    monkeypatch.setenv("COLUMNS", "80")
    text = _help(capsys, cmd)
    summary = next(c.help for c in COMMANDS if c.name == cmd)
    assert len(summary) <= 78, summary
    body = text.split("\n\n", 1)[1]                     # after the usage (it may wrap)
    first, rest = (body.split("\n", 1) + [""])[:2]
    assert first == summary, (cmd, text[:400])
    assert rest.startswith("\n") or not rest.strip(), text[:400]   # a line of its own
    top = _help(capsys)
    assert re.search(rf"\n    {re.escape(cmd)}\s+{re.escape(summary[:30])}", top), top


@pytest.mark.parametrize("cmd", [None] + [c.name for c in COMMANDS])
def test_no_help_prints_a_doubled_percent_sign(cmd, capsys):
    text = _help(capsys, *([cmd] if cmd else []))
    assert "%%" not in text, [ln for ln in text.splitlines() if "%%" in ln]


def test_the_calculators_field_factor_help_says_its_percentages(capsys):
    text = " ".join(_help(capsys, "visibility").split())
    assert "99.93% detection" in text and "50%" in text


# -- 8: a reversed range ---------------------------------------------------------------------
@pytest.mark.parametrize("given, said", [
    ("10-1", "--frames 10-1: the range is reversed (the end is before the start); give 1-10"),
    ("1-4,20-11x3", "--frames 20-11x3: the range is reversed (the end is before the start); "
     "give 11-20x3")])
def test_a_reversed_frame_range_is_called_reversed(given, said, capsys):
    with pytest.raises(SystemExit) as e:
        main(["run", "a.####.exr", "b.####.png", "--frames", given])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ocl-tonemap ERROR: {said} "), err
    from ocl_tonemap.base.quantities import RUN
    with pytest.raises(ValueError, match=re.escape(said)):
        RUN["frames"].check(given, "--frames")


# -- 9: a folder that cannot be written ------------------------------------------------------
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="no /proc here")
@pytest.mark.parametrize("name", ["out.png", "out.jpg", "out.exr", "out.####.png"])
def test_an_unwritable_output_folder_is_named_not_a_full_disk(sample_dir, name, capsys):
    """/proc takes no files and reports no free space: the folder is what is wrong."""
    pattern, frames = sample_dir
    src = pattern if "#" in name else frame_path(pattern, frames[0])
    rc = main(["run", src, f"/proc/{name}", "--frames", f"{frames[0]}-{frames[1]}",
               "--backend", "reference"] if "#" in name else
              ["run", src, f"/proc/{name}", "--backend", "reference"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("ocl-tonemap ERROR: /proc: the folder is not writable"), err
    assert "no space" not in err and "no such file" not in err, err


def test_a_writable_folder_keeps_nothing_but_the_output(sample_dir, tmp_path):
    pattern, frames = sample_dir
    assert main(["run", frame_path(pattern, frames[0]), str(tmp_path / "o.png"),
                 "--backend", "reference", "-q"]) == 0
    assert os.listdir(tmp_path) == ["o.png"]


# -- 10: the defaults in `displays` ----------------------------------------------------------
@pytest.mark.parametrize("config", ["ocl-tonemap", "ocio://default"])
def test_displays_marks_the_default_display_and_view(config):
    from ocl_tonemap.colour import default_display, default_view, load_config
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "displays", "--colorconfig",
                        config], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    cfg = load_config(config)
    d = default_display(cfg)
    lines = [ln for ln in r.stdout.splitlines() if ": " in ln and not ln.startswith("config")]
    marked = [ln for ln in lines if ln.split(": ", 1)[0].endswith(" (default)")]
    assert [ln.split(" (default): ")[0] for ln in marked] == [d], r.stdout
    views = marked[0].split(": ", 1)[1]
    assert f"{default_view(cfg, d)} (default)" in views, r.stdout
    assert "(default): what run uses without --display and --view" in r.stdout, r.stdout
    if config == "ocl-tonemap":
        assert "sRGB - Display (default): Un-tone-mapped (default), Raw" in r.stdout


# -- 11: simulate's outputs sort in time order -----------------------------------------------
def test_simulate_names_sort_in_time_order(sample_dir, tmp_path, capsys):
    pattern, frames = sample_dir
    src = frame_path(pattern, frames[0])
    a = tmp_path / "a"
    a.mkdir()
    assert main(["simulate", src, str(a / "out.png"), "--preadapt", "1000", "--at",
                 "16m,1m,2m,4m", "--backend", "reference"]) == 0
    said = re.findall(r"^t = (\S+) s -> (.*)$", capsys.readouterr().out, re.M)
    names = ["out_t0060s.png", "out_t0120s.png", "out_t0240s.png", "out_t0960s.png"]
    assert sorted(os.listdir(a)) == names
    assert [(t, os.path.basename(p)) for t, p in said] == list(zip(
        ["60", "120", "240", "960"], names)), said
    b = tmp_path / "b"                                  # sub-second times, and wider ones
    b.mkdir()
    assert main(["simulate", src, str(b / "s.exr"), "--preadapt", "1000", "--at",
                 "10,0.5,1.5,1,12000", "--backend", "reference", "-q"]) == 0
    got = sorted(os.listdir(b))
    times = [float(oiio.ImageBuf(str(b / n)).spec().getattribute("ocltm:elapsed_s"))
             for n in got]
    assert times == [0.5, 1.0, 1.5, 10.0, 12000.0], got
    assert got[0] == "s_t00000p5s.exr" and got[-1] == "s_t12000p0s.exr", got


# -- 12: the adaptation plot -----------------------------------------------------------------
@pytest.fixture(scope="module")
def short_tunnel(tmp_path_factory):
    from ocl_tonemap.io.sample import write_tunnel_sequence
    return write_tunnel_sequence(str(tmp_path_factory.mktemp("tunnel")), 48, 27, 8.0, 1.0)


@pytest.mark.parametrize("operator", ["pattanaik00", "ledda04", "durand00", "kirk11"])
def test_the_plot_shows_each_operators_adapted_state_and_says_what_its_lines_mark(
        short_tunnel, tmp_path, operator):
    pattern, _ = short_tunnel
    plot = tmp_path / "p.png"
    assert main(["run", pattern, str(tmp_path / "o.####.png"), "--operator", operator,
                 "--backend", "reference", "--plot", str(plot), "-q"]) == 0
    legends = json.loads(oiio.ImageBuf(str(plot)).spec().getattribute("ocltm:legends"))
    top = legends["adaptation over time"]
    assert "G_cone (goal)" in top and "G_rod (goal, scotopic)" in top
    if operator == "ledda04":            # per-pixel state: no one adapted level, no curves
        assert not [t for t in top if "adapted" in t or t.startswith("A_")], top
        return
    cone = [t for t in top if t.startswith(("A_cone", "L_a cone"))]
    rod = [t for t in top if t.startswith(("A_rod", "L_a rod"))]
    assert cone and rod, top             # durand00 too: its filtered thresholds' levels
    marks = [t for t in top if "mapping" in t]
    if operator == "kirk11":             # local range reduction: no one mapping curve
        assert "scene-to-display mapping" not in legends and not marks, legends
        return
    # the lines over the top panel mark the frames whose curves the mapping panel draws
    assert marks == ["frames of the mapping curves below, in their colours"], top
    assert len(legends["scene-to-display mapping"]) >= 2, legends


@pytest.mark.parametrize("mode", ["default", "paper"])
def test_the_plot_shows_the_slow_course_that_runs(short_tunnel, tmp_path, mode):
    """The second panel: the shared pigment course's bleached fractions by default
    (issue 66), the paper's own B with --mode paper."""
    pattern, _ = short_tunnel
    plot = tmp_path / "p.png"
    assert main(["run", pattern, str(tmp_path / "o.####.png"), "--backend", "reference",
                 "--mode", mode, "--plot", str(plot), "-q"]) == 0
    legends = json.loads(oiio.ImageBuf(str(plot)).spec().getattribute("ocltm:legends"))
    second = [v for k, v in legends.items() if "bleach" in " ".join(v) or "B_" in " ".join(v)]
    assert second, legends
    if mode == "default":
        assert second[0] == ["cones' pigment bleached", "rods' pigment bleached"], legends
    else:
        assert second[0] == ["B_cone", "B_rod"], legends


# -- 13: the calculator's symbols are the run's ----------------------------------------------
def test_the_calculator_says_l_s_for_the_background_given_and_l_b_with_the_veil(capsys):
    argv = ["visibility", "--background", "105.9", "--veil", "80.1", "--target", "1.96",
            "--size", "6"]
    assert main(argv) == 0
    rows = {ln.split("  ")[0].strip(): ln.split("  ", 1)[1].strip()
            for ln in capsys.readouterr().out.splitlines() if "  " in ln}
    assert rows["surround L_s (the background given)"] == "105.9 cd/m^2", rows
    assert rows["veil Lveil"] == "80.1 cd/m^2", rows
    assert rows["L_b = L_s + Lveil"] == "186 cd/m^2", rows
    assert not [k for k, v in rows.items() if "L_b" in k and v.startswith("105.9")], rows
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["L_s"], out["Lveil"], out["L_b"]) == (105.9, 80.1, 186.0)
    assert (out["background"], out["veil"]) == (105.9, 80.1)      # the old keys kept
    text = " ".join(_help(capsys, "visibility").split())
    assert "--background L the target's surround luminance L_s" in text, text
