"""Reading the project's Markdown as a user reads it: the command lines in its code
blocks, the inline code of its prose, its links and headings (tests/docs/)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[2]
#: Where commands and options are shown: the front door and every page under docs/.
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Code blocks in these languages hold no shell commands.
NOT_SHELL = {"python", "py", "json", "yaml", "toml", "xml", "c", "opencl"}
PROGRAM = "ocl-tonemap"


class Line(NamedTuple):
    page: Path
    number: int          # 1-based, the first line of a continued command
    text: str

    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.number}"


def blocks(text: str):
    """(language, first line number of the body, body lines) of each fenced block."""
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^(\s*)(```+|~~~+)\s*([\w+-]*)", lines[i])
        if not m:
            i += 1
            continue
        fence, lang, start = m.group(2), m.group(3).lower(), i + 1
        j = start
        while j < len(lines) and not lines[j].strip().startswith(fence):
            j += 1
        yield lang, start + 1, lines[start:j]
        i = j + 1


def prose(text: str) -> str:
    """The text outside fenced blocks (their lines blanked, so numbers stay)."""
    lines = text.splitlines()
    for _, first, body in blocks(text):
        for k in range(first - 1, first - 1 + len(body)):
            lines[k] = ""
        for k in (first - 2, first - 1 + len(body)):      # the fences
            if 0 <= k < len(lines):
                lines[k] = ""
    return "\n".join(lines)


def _without_comment(line: str) -> str:
    """A shell line without its trailing ``# comment`` (a ``#`` inside a word, as in
    ``shot.####.exr``, is not one)."""
    return re.split(r"(?:^|\s)#(?:\s|$)", line, maxsplit=1)[0].rstrip()


def _synopsis_continues(text: str, raw: str) -> bool:
    """A synopsis's next line: indented, opening with an option (``[--x``, ``--x``,
    ``[run options]``), after a line of an ``ocl-tonemap`` command (``--help``'s layout:
    no backslash)."""
    return bool(re.match(r"^\s+[\[(-]", raw)) and PROGRAM in text


def shell_lines(page: Path):
    """Each logical line of each shell block: continuations joined (a backslash, or a
    synopsis's indented option lines), comments and heredoc bodies dropped."""
    for lang, first, body in blocks(page.read_text()):
        if lang in NOT_SHELL:
            continue
        k, heredoc = 0, None
        while k < len(body):
            number, raw = first + k, body[k]
            k += 1
            if heredoc is not None:
                if raw.strip() == heredoc:
                    heredoc = None
                continue
            text = _without_comment(raw)
            while k < len(body):
                if text.endswith("\\"):
                    text = text[:-1] + " " + _without_comment(body[k]).lstrip()
                elif _synopsis_continues(text, body[k]):
                    text = text + " " + _without_comment(body[k]).lstrip()
                else:
                    break
                k += 1
            m = re.search(r"<<-?\s*['\"]?(\w+)['\"]?", text)
            if m:
                heredoc = m.group(1)
            if text.strip():
                yield Line(page, number, text.strip())


#: A shell line's separators: what follows one is a new command.
_SEPARATORS = {"&&", "||", ";", "|", "&", "(", ")"}
_REDIRECTS = {">", ">>", "<", ">&", "<&", ">|", "&>"}
#: Stands for a synopsis's ``|`` while a line is split into words.
ALT = "\x00"


def commands(line: Line):
    """The ``ocl-tonemap`` commands of one shell line, each as its argument list
    (without the program's name): a line may hold several (``a && ocl-tonemap ...``),
    a ``$ `` prompt, environment assignments before the program, redirections after
    it. A command inside ``$(...)`` counts too."""
    text = line.text
    if not re.search(r"(?:^|[\s;&|(])ocl-tonemap(?:\s|\)|$)", text):
        return []
    if text.startswith("$ "):
        text = text[2:]
    # a | between two words is a synopsis's alternative (auto|always), not a pipe
    text = re.sub(r"(?<=[^\s|])\|(?=[^\s|])", ALT, text)
    lex = shlex.shlex(text, posix=True, punctuation_chars=";&|()<>")
    lex.whitespace_split = True
    lex.commenters = ""
    words = [w.replace(ALT, "|") for w in lex]
    out, cmd, skip = [], [], False
    for w in words + [";"]:
        if skip:
            skip = False
            continue
        if w in _SEPARATORS:
            if cmd:
                out.append(cmd)
            cmd = []
        elif w in _REDIRECTS:
            skip = True
        elif not cmd and re.match(r"^[A-Za-z_]\w*=", w):
            continue                              # VAR=value before the program
        else:
            cmd.append(w)
    inner = [c for w in words for c in re.findall(r"\$\((ocl-tonemap [^)]*)\)", w)]
    found = [c[1:] for c in out if c and c[0] == PROGRAM]
    return found + [shlex.split(c)[1:] for c in inner]


def inline_code(page: Path):
    """(line number, text) of each inline code span of the page's prose."""
    text = prose(page.read_text())
    for m in re.finditer(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)", text, re.S):
        yield text.count("\n", 0, m.start()) + 1, " ".join(m.group(2).split())


def flags_in(span: str):
    """The long flags a span of inline code names, each with the alternatives it
    shows (``--flare on|off|auto`` -> ("--flare", ["on", "off", "auto"])), else []."""
    for m in re.finditer(r"(?<![\w-])(--[a-z][a-z0-9-]*)(?:[ =]([^\s\[\]]+))?", span):
        value = m.group(2) or ""
        alts = value.split("|") if "|" in value and not value.startswith("-") else []
        yield m.group(1), [a for a in alts if a]


class Link(NamedTuple):
    page: Path
    number: int
    target: str


def links(page: Path):
    """Relative links and images of a page's prose: ``[..](target)``."""
    text = prose(page.read_text())
    for m in re.finditer(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)", text):
        target = m.group(1)
        if re.match(r"^[a-z]+:", target):          # http:, https:, mailto:
            continue
        yield Link(page, text.count("\n", 0, m.start()) + 1, target)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    s = heading.strip().lower()
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def anchors(page: Path) -> set:
    out, seen = set(), {}
    for line in prose(page.read_text()).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            s = slug(m.group(1))
            n = seen.get(s, 0)
            seen[s] = n + 1
            out.add(s if n == 0 else f"{s}-{n}")
    return out
