"""Bad input found by trying the commands as a user would (issue 58's trial): each is
refused in one line naming the flag or file, exit 2, before anything is written; no
input is ever overwritten; nothing the command made is left behind."""

from __future__ import annotations

import os

import pytest

from ocl_tonemap.cli.table import main


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("left")
    pattern, frames = write_tunnel_sequence(str(d / "s"), 16, 9, 10.0, 0.3)
    return d, pattern, frames


def _refused(argv, capsys, *words) -> str:
    try:
        rc = main(argv)
    except SystemExit as e:
        rc = e.code
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if "ERROR" in ln]
    assert rc == 2 and len(errors) == 1, err
    assert "Traceback" not in err
    for w in words:
        assert w in errors[0], err
    return errors[0]


def test_a_job_file_never_overwrites_a_frame(seq, capsys):
    d, pattern, frames = seq
    first = pattern.replace("####", f"{frames[0]:04d}")
    before = open(first, "rb").read()
    _refused(["farm-template", pattern, str(d / "o.####.png"), "--format", "openjd", "-o",
              first], capsys, "-o", "input frame")
    assert open(first, "rb").read() == before
    _refused(["farm-template", pattern, str(d / "o.####.png"), "--format", "opencue", "-o",
              str(d / "j.xml"), "--command", " "], capsys, "--command")
    _refused(["farm-template", pattern, str(d / "o.####.png"), "--format", "opencue", "-o",
              str(d / "j.xml"), "--colorconfig", "ocio://nonexistent"], capsys, "nonexistent")
    assert not (d / "j.xml").exists()


def test_plot_and_state_paths_are_checked_before_the_first_frame(seq, tmp_path, capsys):
    d, pattern, _ = seq
    still = pattern.replace("####", "0001")
    out = tmp_path / "o.png"
    _refused(["run", still, str(out), "--plot", str(tmp_path / "p.xyz")], capsys,
             "--plot", ".xyz")
    (tmp_path / "sdir").mkdir()
    _refused(["run", still, str(out), "--state-out", str(tmp_path / "sdir")], capsys,
             "sdir", "is a folder")
    _refused(["simulate", still, str(tmp_path / "m.exr"), "--at", "1", "--preadapt", "10",
              "--plot", str(tmp_path / "p.xyz")], capsys, "--plot")
    assert sorted(os.listdir(tmp_path)) == ["sdir"]


def test_a_failed_demo_takes_back_what_it_made(tmp_path, capsys):
    _refused(["demo", str(tmp_path / "dd"), "--seconds", "0.1", "--size", "16x16",
              "--frames", "50-60"], capsys, "missing frame")
    assert not (tmp_path / "dd").exists()
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "mine.txt").write_text("x")
    _refused(["demo", str(tmp_path / "kept"), "--seconds", "0.1", "--size", "16x16",
              "--frames", "50-60"], capsys, "missing frame")
    assert os.listdir(tmp_path / "kept") == ["mine.txt"]


def test_sample_into_a_file_or_nowhere(seq, capsys):
    d, pattern, _ = seq
    still = pattern.replace("####", "0001")
    _refused(["sample", still], capsys, still, "is a file")
    if os.path.isdir("/proc") and not os.access("/proc", os.W_OK) or \
            os.path.isdir("/proc") and os.statvfs("/proc").f_bavail == 0:
        _refused(["sample", "/proc/nope", "--seconds", "0.1", "--size", "8x8"], capsys,
                 "/proc/nope", "cannot be written")


def test_a_negative_value_read_as_a_flag_says_how_to_write_it(seq, capsys):
    d, pattern, _ = seq
    _refused(["run", pattern.replace("####", "0001"), str(d / "n.png"), "--exposure",
              "-inf"], capsys, "--exposure=")


def test_shot_flags_on_a_plain_run_are_said_to_be_ignored(seq, caplog):
    import logging
    d, pattern, _ = seq
    with caplog.at_level(logging.WARNING, logger="ocl_tonemap"):
        assert main(["run", pattern.replace("####", "0001"), str(d / "w.png"), "--workers",
                     "4", "--store", str(d / "st")]) == 0
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "--workers applies to --scheduler" in said and "--store applies to" in said
    assert not (d / "st").exists()
