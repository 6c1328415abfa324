"""docs/cli.md, the command reference, is what ``python -m ocl_tonemap.cli.docs`` writes
from the parser now (issue 58, part 5); the text depends on the parser alone, not on
the terminal's width or the plugins installed."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

from ocl_tonemap.cli import docs as cli_docs
from ocl_tonemap.cli.table import build_parser

import mdscan  # tests/docs/mdscan.py (pytest puts this folder on sys.path)

CLI_MD = mdscan.ROOT / "docs" / "cli.md"


def test_docs_cli_md_is_current():
    """``--check``, as CI would run it: exit 0, the committed file is the generator's."""
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap.cli.docs", "--check"],
                       cwd=mdscan.ROOT, capture_output=True, text=True)
    assert r.returncode == 0, (r.stderr + "\nregenerate: python -m ocl_tonemap.cli.docs")
    assert CLI_MD.read_text(encoding="utf-8") == cli_docs.render()


def test_check_says_when_the_file_is_stale(tmp_path, capsys):
    stale = tmp_path / "cli.md"
    stale.write_text(cli_docs.render().replace("--rods", "--rodz"), encoding="utf-8")
    assert cli_docs.main(["--check", "--out", str(stale)]) == 1
    assert "stale" in capsys.readouterr().err
    assert cli_docs.main(["--check", "--out", str(tmp_path / "missing.md")]) == 1
    assert cli_docs.main(["--out", str(stale)]) == 0
    assert cli_docs.main(["--check", "--out", str(stale)]) == 0


def test_the_reference_does_not_depend_on_the_terminal(tmp_path):
    """Written under a 40- and a 300-column terminal, twice each: the same bytes."""
    outs = []
    for cols in ("40", "300", "40"):
        out = tmp_path / f"cli{cols}-{len(outs)}.md"
        env = {**os.environ, "COLUMNS": cols, "LINES": "20", "FORCE_COLOR": "1"}
        subprocess.run([sys.executable, "-m", "ocl_tonemap.cli.docs", "--out", str(out)],
                       cwd=mdscan.ROOT, env=env, check=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2] == cli_docs.render().encode()


def test_every_sub_command_and_every_shown_flag_is_in_it():
    text = cli_docs.render()
    ap = build_parser()
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sub.choices.items():
        assert f"## `ocl-tonemap {name}`" in text, name
        for a in p._actions:
            if a.help is argparse.SUPPRESS or not a.option_strings:
                continue
            assert f"`{a.option_strings[-1]}" in text, (name, a.option_strings)
            for c in a.choices or ():
                assert str(c) in text, (name, a.option_strings, c)
    # the table of sub-commands links each one's section
    anchors = mdscan.anchors(CLI_MD) if CLI_MD.exists() else set()
    for name in sub.choices:
        assert f"ocl-tonemap-{name}" in anchors, name
