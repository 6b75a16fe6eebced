"""The documentation holds together: README and docs/*.md links and anchors resolve inside the repository,
the README opens with the two commands, and docstrings cite sections of docs/design.md that exist."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.paths import ROOT

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: ``[text](target)`` and ``![alt](target)``; the target ends at the first space or closing parenthesis.
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
#: What docstrings write to point at the design: ``docs/design.md section 4.4`` (or ``section 5``).
CITATION = re.compile(r"docs/design\.md section (\d+(?:\.\d+)?)")


def _prose(text: str) -> str:
    """The text outside fenced code blocks and inline code spans (links there are examples, not links)."""
    text = re.sub(r"^```.*?^```[^\n]*$", "", text, flags=re.S | re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def github_slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped (word characters, spaces and
    hyphens kept), spaces to hyphens."""
    text = re.sub(r"`", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file, with GitHub's ``-1``, ``-2`` suffixes for repeats."""
    text = re.sub(r"^```.*?^```[^\n]*$", "", path.read_text(encoding="utf-8"), flags=re.S | re.M)
    seen: dict[str, int] = {}
    out = set()
    for m in re.finditer(r"^#{1,6}\s+(.+?)\s*#*\s*$", text, flags=re.M):
        slug = github_slug(m.group(1))
        n = seen.get(slug, 0)
        out.add(slug if n == 0 else f"{slug}-{n}")
        seen[slug] = n + 1
    return out


def test_github_slug_rules():
    assert github_slug("4.4 Change measure (eq 6-7)") == "44-change-measure-eq-6-7"
    assert github_slug("The paper's findings, checked") == "the-papers-findings-checked"
    assert github_slug("`omnijax` and friends") == "omnijax-and-friends"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_and_anchors_resolve(doc: Path):
    """Every relative link of the file names a file of the repository (not outside it, as a user's
    clone has nothing there), and every #anchor names a heading of its target."""
    bad = []
    for target in LINK.findall(_prose(doc.read_text(encoding="utf-8"))):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path_part, _, anchor = target.partition("#")
        path = (doc.parent / path_part).resolve() if path_part else doc
        if not path.is_relative_to(ROOT):
            bad.append(f"{target}: outside the repository")
        elif not path.exists():
            bad.append(f"{target}: no such file")
        elif anchor and (path.suffix != ".md" or anchor not in anchors(path)):
            bad.append(f"{target}: no heading with anchor #{anchor} in {path.relative_to(ROOT)}")
    assert not bad, f"{doc.relative_to(ROOT)}: " + "; ".join(bad)


def test_links_are_found():
    """The link pattern sees links (so that the test above cannot pass by finding none)."""
    readme = _prose((ROOT / "README.md").read_text(encoding="utf-8"))
    targets = LINK.findall(readme)
    assert "docs/design.md" in targets and "docs/demo_view.png" in targets


def test_readme_opens_with_the_two_commands():
    head = "\n".join((ROOT / "README.md").read_text(encoding="utf-8").splitlines()[:40])
    assert "make demo" in head and "make test" in head


def test_design_citations_name_existing_sections():
    """``docs/design.md section N.M`` in code and tests names a numbered heading of the design."""
    sections = set(re.findall(r"^#{2,3} (\d+(?:\.\d+)?) ", (ROOT / "docs" / "design.md").read_text(encoding="utf-8"),
                              flags=re.M))
    cited, bad = 0, []
    for py in sorted(ROOT.glob("**/*.py")):
        if ".venv" in py.parts or py == Path(__file__).resolve():
            continue
        text = py.read_text(encoding="utf-8")
        for m in CITATION.finditer(text):
            cited += 1
            if m.group(1) not in sections:
                bad.append(f"{py.relative_to(ROOT)}: section {m.group(1)}")
        if "DESIGN" + ".md" in text:
            bad.append(f"{py.relative_to(ROOT)}: cites DESIGN.md, which is not in the repository")
    assert cited >= 20 and not bad, bad
