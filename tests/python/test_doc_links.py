"""Every relative link of the documentation leads somewhere: README.md and docs/**/*.md.

A link (`[text](target)`, `![alt](target)`, a reference definition `[name]: target`, or an
HTML `href=`/`src=`) whose target has no scheme is resolved as GitHub resolves it: relative to
the file that holds it (from the repository's root when it starts with `/`); the file or folder
must exist inside the repository. A `#fragment` must name a heading of the target Markdown file
(the file itself when the path is empty), by GitHub's anchor rules: the heading's text as
rendered, lower-cased, every character that is not a letter, digit, `_`, `-` or space dropped,
each space a `-`, and `-1`, `-2`, ... after a repeated one; or an `<a name=...>`/`id=...`
written out. Links inside code (fenced, indented, or in backticks) and HTML comments are not
links. Web addresses are not fetched.

Pure text: it needs neither the command line nor the module, and runs in well under a second.
"""

import re
from pathlib import Path

import pytest

from helpers import ROOT

FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
DEFINITION = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+\"[^\"]*\")?\s*$")
HTML_TARGET = re.compile(r"""\b(?:href|src)\s*=\s*["']([^"']*)["']""")
HTML_ANCHOR = re.compile(r"""<a\s[^>]*\b(?:name|id)\s*=\s*["']([^"']+)["']""")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:|^//")


def documents() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def prose(markdown: str) -> list[tuple[int, str]]:
    """(line number, text) of the lines that are not code, with code spans and HTML comments
    blanked out: where links and headings can be."""
    text = re.sub(r"<!--.*?-->", lambda m: "\n" * m.group(0).count("\n"), markdown, flags=re.S)
    out: list[tuple[int, str]] = []
    fence = None
    indented = False
    previous_blank = True
    for number, line in enumerate(text.splitlines(), start=1):
        if fence:
            if line.strip().startswith(fence):
                fence = None
            previous_blank = False
            continue
        if m := FENCE.match(line):
            fence = m.group(1)
            previous_blank = False
            continue
        blank = not line.strip()
        if not blank and line.startswith(("    ", "\t")) and (previous_blank or indented):
            indented = True
            previous_blank = False
            continue
        if not blank:
            indented = False
        previous_blank = blank
        out.append((number, re.sub(r"(`+)(.+?)\1", lambda m: " " * len(m.group(0)), line)))
    return out


def slug(heading: str) -> str:
    """GitHub's anchor of a heading (github-slugger on the rendered text)."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link's text, an image's alt
    text = re.sub(r"<[^>]+>", "", text).replace("`", "").replace("*", "")
    text = re.sub(r"[^\w\- ]", "", text.lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    markdown = path.read_text(encoding="utf-8")
    found: set[str] = set()
    seen: dict[str, int] = {}
    for _, line in prose_with_code_spans(markdown):
        if m := HEADING.match(line):
            base = slug(m.group(2))
            n = seen.get(base, 0)
            seen[base] = n + 1
            found.add(base if n == 0 else f"{base}-{n}")
        found.update(HTML_ANCHOR.findall(line))
    return found


def prose_with_code_spans(markdown: str) -> list[tuple[int, str]]:
    """As `prose`, but a heading keeps its code spans (their text is in its anchor)."""
    lines = markdown.splitlines()
    return [(n, lines[n - 1]) for n, _ in prose(markdown)]


def links(markdown: str) -> list[tuple[int, str]]:
    found = []
    for number, line in prose(markdown):
        found += [(number, t) for t in INLINE.findall(line)]
        found += [(number, t) for t in HTML_TARGET.findall(line)]
        if m := DEFINITION.match(line):
            found.append((number, m.group(1)))
    return found


def broken(path: Path, root: Path = ROOT) -> list[str]:
    """Every link of the file at `path` that leads nowhere, as `file:line: target: why`."""
    problems = []
    for number, target in links(path.read_text(encoding="utf-8")):
        where = f"{path.relative_to(root)}:{number}: {target}"
        if not target:
            problems.append(f"{where}: an empty link")
            continue
        if SCHEME.match(target):
            continue
        file_part, _, fragment = target.partition("#")
        if not file_part:
            dest = path
        elif file_part.startswith("/"):
            dest = root / file_part.lstrip("/")
        else:
            dest = path.parent / file_part
        dest = Path(re.sub(r"%20", " ", str(dest))).resolve()
        if not dest.is_relative_to(root.resolve()):
            problems.append(f"{where}: outside the repository")
            continue
        if not dest.exists():
            problems.append(f"{where}: no such file or folder")
            continue
        if fragment:
            if dest.suffix == ".md" and dest.is_file():
                if fragment not in anchors(dest):
                    problems.append(f"{where}: no heading or anchor `{fragment}` in {dest.name}")
            elif not re.fullmatch(r"L\d+(-L\d+)?", fragment):
                problems.append(f"{where}: a fragment on a file that has no headings")
    return problems


@pytest.mark.parametrize("path", documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_and_anchor_resolves(path: Path):
    assert path.is_file()
    problems = broken(path)
    assert not problems, "broken links:\n" + "\n".join(problems)


def test_the_docs_are_linked_and_have_links_to_check():
    """The check sees the links that are there: the front page links into docs/, the index
    links every file beside it, and their anchors are found."""
    readme = links((ROOT / "README.md").read_text(encoding="utf-8"))
    assert sum(t.startswith("docs/") for _, t in readme) >= 10, readme
    index = {t.partition("#")[0] for _, t in links((ROOT / "docs" / "README.md").read_text(encoding="utf-8"))}
    missing = [p.name for p in sorted((ROOT / "docs").glob("*.md")) if p.name != "README.md" and p.name not in index]
    assert not missing, f"docs/README.md does not link {missing}"
    assert "samplers-randomised-quasi-monte-carlo-planes" in anchors(ROOT / "docs" / "estimators.md")


def test_a_broken_link_or_anchor_is_found(tmp_path: Path):
    """The checker itself: each kind of broken link is reported, and a good one is not."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "other.md").write_text("# Other page\n\n## On a GPU: `--device`\n\n## Twice\n\n## Twice\n")
    (tmp_path / "picture.png").write_bytes(b"")
    page = tmp_path / "README.md"
    page.write_text(
        "# Top\n\n"
        "[fine](docs/other.md#on-a-gpu---device) [fine](docs/other.md#twice-1) ![fine](picture.png)\n"
        "[fine](#top) [web](https://example.com/x#y) `[code](nowhere.md)`\n\n"
        "    [indented code](nowhere.md)\n\n"
        "```sh\n[fenced](nowhere.md)\n```\n\n"
        "<!-- [comment](nowhere.md) -->\n"
        "[missing file](docs/nowhere.md)\n"
        "[missing anchor](docs/other.md#on-a-cpu)\n"
        "[missing own anchor](#bottom) [third twice](docs/other.md#twice-2)\n"
        '<img src="missing.png"> [escape](../../etc/passwd)\n'
        "[ref]: docs/gone.md\n",
        encoding="utf-8",
    )
    problems = broken(page, root=tmp_path)
    assert [p.split(": ")[1] for p in problems] == [
        "docs/nowhere.md", "docs/other.md#on-a-cpu", "#bottom", "docs/other.md#twice-2",
        "../../etc/passwd", "missing.png", "docs/gone.md",
    ], problems
