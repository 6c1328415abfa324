"""Every ``ocl-tonemap`` command line the README and docs/*.md show, checked against the
real parser (issue 58, part 5): each flag exists for its sub-command, each choice and
each alternative of a synopsis (``--rods auto|always``) is one the parser takes, a
concrete command line parses as written, and a range the prose states for a flag
(```--fov` 0..360``) is the one its help states.

A command line is read from fenced shell blocks (continuations joined, comments,
heredocs and redirections dropped, several commands of one line apart) and from inline
code that starts with the program. A line is a *synopsis* when it shows optional parts
(``[--x]``), alternatives (``a|b``), ``...`` or a placeholder for a flag's value
(``--fov DEG``, ``X,Y,SIZE``): its flags and concrete values are checked one by one;
any other line is parsed whole with ``build_parser().parse_args``. Shell variables
(``$VAR``, ``"$(...)"``) are placeholders.
"""

from __future__ import annotations

import argparse
import math
import re
from functools import lru_cache

import pytest

from ocl_tonemap.cli.table import build_parser

import mdscan  # tests/docs/mdscan.py (pytest puts this folder on sys.path)

#: Flags of other programs that the prose names in inline code of their own (the
#: benchmarks' options; ``oiiotool --frames`` is read as oiiotool's, its span opening
#: with the program): not ocl-tonemap's.
OTHER_PROGRAMS_FLAGS = {
    "--out-dir", "--out", "--sections",    # the benchmarks' (docs/benchmarks.md)
    "--compare",                           # benchmarks.equivalence (docs/architecture.md)
    "--ociodisplay",                       # oiiotool's (docs/ocio_export.md)
}
#: Flags the docs name to say that there is no such flag.
NO_SUCH_FLAG = {"--ocio-export-partial"}
#: docs/backends.md shows the example plugin operator (examples/: ``exposure``, its
#: ``--exposure-key``), which exists once that package is installed.
PLUGIN = {"operator": {"exposure"}, "flags": {"--exposure-key"}}


# -- the parser ------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def parser() -> argparse.ArgumentParser:
    return build_parser()


@lru_cache(maxsize=1)
def subparsers() -> dict:
    sub = next(a for a in parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def actions(p: argparse.ArgumentParser) -> dict:
    """option string -> action, shown in --help or accepted without being listed."""
    return {o: a for a in p._actions for o in a.option_strings}


def all_flags() -> dict:
    """option string -> the actions of every sub-command (and the top level) that take it."""
    out: dict = {}
    for p in [parser(), *subparsers().values()]:
        for o, a in actions(p).items():
            out.setdefault(o, []).append(a)
    return out


def accepts(action: argparse.Action, value: str) -> str | None:
    """None when ``action`` takes ``value`` (its choices, its type's check), else why not."""
    if action.nargs == 0:
        return f"{action.option_strings[0]} takes no value"
    try:
        v = action.type(value) if callable(action.type) else value
    except (argparse.ArgumentTypeError, ValueError, TypeError) as e:
        return f"{action.option_strings[0]} {value}: {e}"
    if action.choices is not None and v not in action.choices:
        return (f"{action.option_strings[0]} {value}: not a choice "
                f"({', '.join(map(str, action.choices))})")
    return None


# -- reading a command -----------------------------------------------------------------------
_PLACEHOLDER = re.compile(r"[A-Z]|\$|\.\.\.|^<.*>$|^[a-z](,[a-z])+$")


def placeholder(value: str, action: argparse.Action | None = None) -> bool:
    """A value the docs show as what to give, not as itself: capitals (DEG, X,Y,SIZE,
    spot:X,Y), a chromaticity's ``x,y``, a shell variable, ``...``, ``<n>``, or the
    flag's own metavar (0-9)."""
    if action is not None and value == action.metavar:
        return True
    return bool(_PLACEHOLDER.search(value))


def _strip(word: str) -> str:
    """A synopsis word without the brackets that open or close optional parts."""
    return word.lstrip("[(").rstrip("])")


def is_synopsis(argv: list[str]) -> bool:
    if any(("[" in w or "]" in w or "|" in w or "..." in w) for w in argv):
        return True
    sub = subparsers().get(argv[0]) if argv else None
    if sub is None:
        return False
    acts = actions(sub)
    for flag, value in zip(argv, argv[1:]):
        a = acts.get(flag.split("=")[0])
        if a is not None and a.nargs != 0 and placeholder(value, a):
            return True
    return any("$" in w for w in argv)


def problems(argv: list[str], partial: bool = False) -> list[str]:
    """What is wrong in one command's arguments (without the program's name); a
    ``partial`` one (inline code in a sentence: ``ocl-tonemap farm-template --format
    openjd``) is checked flag by flag, as a synopsis, not parsed whole."""
    k = next((i for i, w in enumerate(argv) if w not in ("-v", "-vv", "-q")), None)
    if k is None:
        return []
    names = [_strip(n) for n in _strip(argv[k]).split("|")]
    unknown = [n for n in names if n not in subparsers()]
    if unknown:
        return [f"no sub-command {', '.join(unknown)} (there are {', '.join(subparsers())})"]
    rest, synopsis = argv[:k] + argv[k + 1:], partial or is_synopsis(argv[k:])
    return [p for n in names for p in _problems_of(subparsers()[n], n, rest, synopsis)]


def _problems_of(p, name: str, rest: list[str], synopsis: bool) -> list[str]:
    if not synopsis:
        if PLUGIN["flags"] & set(rest) or set(rest) & PLUGIN["operator"]:
            return []                      # the example plugin's (docs/backends.md)
        try:
            parser().parse_args([name, *rest])
        except SystemExit as e:
            return [f"{name} {' '.join(rest)}: the parser refuses it (exit {e.code})"]
        return []
    acts, out, takes = actions(p), [], None    # takes: the flag whose value comes next
    for word in rest:
        alts = [a for a in (_strip(x) for x in _strip(word).split("|")) if a]
        if any(a.startswith("-") for a in alts):
            takes = None
            for alt in alts:
                if not alt.startswith("-"):
                    out += _value_problems(name, takes, alt) if takes else []
                    continue
                flag, _, value = alt.partition("=")
                flag = "-v" if flag == "-vv" else flag
                act = acts.get(flag)
                if act is None:
                    out.append(f"{name}: no flag {flag}")
                elif value:
                    out += _value_problems(name, act, value)
                elif act.nargs != 0:
                    takes = act
        else:
            for alt in alts if takes is not None else []:
                out += _value_problems(name, takes, alt)
            takes = None
    return out


def _value_problems(name: str, action: argparse.Action, value: str) -> list[str]:
    if placeholder(value, action):
        return []
    why = accepts(action, value)
    return [f"{name}: {why}"] if why else []


def commands():
    """(where, argv, partial) of every ocl-tonemap command the pages show: whole in
    shell blocks, partial in inline code."""
    for page in mdscan.PAGES:
        for line in mdscan.shell_lines(page):
            for argv in mdscan.commands(line):
                yield line.where(), argv, False
        for number, span in mdscan.inline_code(page):
            words = span.split()
            if words[0] == mdscan.PROGRAM and len(words) > 1 and \
                    re.match(r"^(-|[a-z][a-z|-]*$)", words[1]):    # not "ocl-tonemap ERROR:"
                line = mdscan.Line(page, number, span)
                for argv in mdscan.commands(line):
                    yield line.where(), argv, True


ALL = list(commands())


def test_the_pages_show_commands():
    """The scanner finds what the pages show (a scanner that finds nothing passes all)."""
    where = {w.split(":")[0] for w, _, _ in ALL}
    assert {"README.md", "docs/guide.md", "docs/visibility.md", "docs/radiance.md"} <= where
    assert len(ALL) > 40
    whole = [a for _, a, part in ALL if not part]
    assert any(is_synopsis(a) for a in whole) and any(not is_synopsis(a) for a in whole)
    assert any(part for _, _, part in ALL)


@pytest.mark.parametrize("where,argv,partial", ALL, ids=[w for w, _, _ in ALL])
def test_every_command_line_parses(where, argv, partial):
    assert problems(argv, partial) == [], f"{where}: ocl-tonemap {' '.join(argv)}"


# -- flags named in the prose ----------------------------------------------------------------
def prose_flags():
    """(where, flag, alternatives) of each ocl-tonemap flag in inline code that is not
    a whole command: ``--rods auto|always``, ``--flare``."""
    for page in mdscan.PAGES:
        if page.name == "cli.md":
            continue                       # written from the parser (test_cli_docs.py)
        for number, span in mdscan.inline_code(page):
            first = span.split()[0] if span.split() else ""
            if not first.startswith("-"):
                continue                   # a command (above) or another program's line
            for flag, alts in mdscan.flags_in(span):
                yield f"{page.relative_to(mdscan.ROOT)}:{number}", flag, alts


PROSE = list(prose_flags())


def test_prose_flags_found():
    assert len(PROSE) > 50


@pytest.mark.parametrize("where,flag,alts", PROSE, ids=[f"{w} {f}" for w, f, _ in PROSE])
def test_every_flag_and_choice_in_the_prose_exists(where, flag, alts):
    if flag in OTHER_PROGRAMS_FLAGS or flag in PLUGIN["flags"]:
        return
    if flag in NO_SUCH_FLAG:
        assert flag not in all_flags(), f"{where}: the docs say there is no {flag}"
        return
    found = all_flags().get(flag)
    assert found, f"{where}: no sub-command has {flag}"
    for alt in alts:
        if any(placeholder(alt, a) for a in found):
            continue
        whys = [accepts(a, alt) for a in found]
        assert any(w is None for w in whys), f"{where}: {flag} {alt}: {whys}"


# -- ranges ----------------------------------------------------------------------------------
_NUM = r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?"
#: ```--fov` 0..360``, ``--fov DEG`` (0..360): a flag in inline code, then a range
#: before the sentence or the clause ends.
_STATED = re.compile(r"`(--[a-z][a-z0-9-]*)[^`]*`[^`.;:()]{0,12}?\(?(" + _NUM + r")\.\.(" +
                     _NUM + r")")


def _help_ranges(action: argparse.Action) -> dict:
    """(low, high) -> whether low itself is taken, of each range the help states:
    ``0..360``, ``> 0 and at most 360``."""
    text = " ".join((action.help or "").split())
    out = {(float(a), float(b)): True
           for a, b in re.findall(r"(" + _NUM + r")\.\.(" + _NUM + r")", text)}
    for a, b in re.findall(r"> (" + _NUM + r") and at most (" + _NUM + r")", text):
        out[(float(a), float(b))] = False
    return out


def stated_ranges():
    for page in mdscan.PAGES:
        if page.name == "cli.md":
            continue
        text = mdscan.prose(page.read_text())
        for m in _STATED.finditer(text):
            number = text.count("\n", 0, m.start()) + 1
            yield (f"{page.relative_to(mdscan.ROOT)}:{number}", m.group(1),
                   float(m.group(2)), float(m.group(3)))


RANGES = list(stated_ranges())


def test_the_fov_range_is_stated_and_found():
    """The range the issue found wrong (0..180): the guide states the parser's 0..360."""
    assert any(f == "--fov" and (lo, hi) == (0, 360) for _, f, lo, hi in RANGES), RANGES


@pytest.mark.parametrize("where,flag,lo,hi", RANGES, ids=[f"{w} {f}" for w, f, _, _ in RANGES])
def test_a_range_the_docs_state_is_the_parsers(where, flag, lo, hi):
    found = all_flags().get(flag)
    assert found, f"{where}: no sub-command has {flag}"
    helped = {r for a in found for r in _help_ranges(a)}
    assert (lo, hi) in helped, f"{where}: {flag} {lo:g}..{hi:g}; the help says {helped}"
    for a in found:
        ranges = _help_ranges(a)
        if (lo, hi) in ranges and a.type is not None:
            ends = (lo, hi) if ranges[(lo, hi)] else (hi,)
            for v in ends:                 # its ends are taken (a low end "> 0": not)
                assert accepts(a, f"{v:g}") is None, f"{where}: {flag} {v:g}"
            past = hi * 1.01 + 1 if math.isfinite(hi) else None
            if past is not None:           # just past the top is refused
                assert accepts(a, f"{past:g}") is not None, f"{where}: {flag} {past:g}"


# -- the checker itself ----------------------------------------------------------------------
@pytest.mark.parametrize("line,wrong", [
    ("ocl-tonemap run a.exr b.png [--rods auto|on]", "--rods on"),
    ("ocl-tonemap run a.exr b.png --rods on", "refuses"),
    ("ocl-tonemap run a.exr b.png [--adrian 1989|rp9]", "--adrian rp9"),
    ("ocl-tonemap run a.exr b.png [--no-such-flag N]", "no flag --no-such-flag"),
    ("ocl-tonemap measure|integrat INPUT OUTPUT", "no sub-command integrat"),
    ("ocl-tonemap run a.exr b.png --fov 400", "refuses"),
    ("ocl-tonemap visibility --background L [--target L|--nope]", "no flag --nope"),
])
def test_the_checker_finds_what_is_wrong(line, wrong):
    from pathlib import Path
    (argv,) = mdscan.commands(mdscan.Line(Path("x.md"), 1, line))
    found = problems(argv)
    assert any(wrong in p for p in found), found


@pytest.mark.parametrize("line", [
    "ocl-tonemap run a.exr b.png [--rods auto|always] [--fov DEG] [--png-level 0-9]",
    "ocl-tonemap run \"$IN\" out/x.####.png --operator durand00 --lut $N",
    "ocl-tonemap measure|integrate|apply INPUT OUTPUT [run options] [--store DIR]",
    "ocl-tonemap run in.exr out.png --fov 200",
])
def test_the_checker_takes_what_is_right(line):
    from pathlib import Path
    (argv,) = mdscan.commands(mdscan.Line(Path("x.md"), 1, line))
    assert problems(argv) == []
