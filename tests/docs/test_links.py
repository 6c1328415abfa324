"""Every relative link and image of README.md and docs/*.md points to a file that
exists, and a link to a heading (``guide.md#calibration-and-colour``) to a heading
that exists (GitHub's anchors) (issue 58, part 5: the README moved into docs/)."""

from __future__ import annotations

import pytest

import mdscan  # tests/docs/mdscan.py (pytest puts this folder on sys.path)

LINKS = [link for page in mdscan.PAGES for link in mdscan.links(page)]


def test_the_pages_have_links():
    assert {link.page.name for link in LINKS} >= {"README.md", "guide.md", "install.md"}
    assert len(LINKS) > 40


@pytest.mark.parametrize("link", LINKS, ids=[f"{ln.page.name}:{ln.number}" for ln in LINKS])
def test_every_relative_link_resolves(link):
    path, _, anchor = link.target.partition("#")
    target = (link.page.parent / path).resolve() if path else link.page
    where = f"{link.page.relative_to(mdscan.ROOT)}:{link.number}"
    assert target.exists(), f"{where}: {link.target} is not a file of the repository"
    assert mdscan.ROOT in target.parents or target == mdscan.ROOT, \
        f"{where}: {link.target} leaves the repository"
    if anchor and target.suffix == ".md":
        assert anchor in mdscan.anchors(target), \
            f"{where}: {target.name} has no heading #{anchor}"


def test_the_front_door_is_short():
    """The README is a front door (at most 250 lines); the rest is in docs/."""
    lines = (mdscan.ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 250, len(lines)
    text = "\n".join(lines)
    for page in ("docs/guide.md", "docs/cli.md", "docs/install.md", "docs/visibility.md"):
        assert f"]({page}" in text, f"the README does not link {page}"
