"""The documentation runs as printed: every ```sh, ```bash and ```python block of the front
page (README.md), then of the guide (docs/guide.md), then of the reference pages that have any
(`WALK` lists them in order), in order.

All blocks run in one temporary working directory, so that a block can use what an earlier one
wrote, as a reader working through the front page and the guide would; the directory holds
links to the repository's `media_scenes` and `tests` (the commands' paths are relative to the
clone's root, wherever the page lies). A page of docs/ that has a block to run and is not in
`WALK` fails `test_every_page_with_blocks_to_run_is_walked`.
A shell block runs with bash (`set -e`: its first failing command fails it), with the command
line built by `cargo build --release` first on PATH as `fogplanes` (FOGPLANES_CLI overrides
its path) and this Python's environment next (so `python3` and `dask` are the venv's); a
Python block runs as a script of its own in this Python.

Comment lines just above a block's opening fence steer it:

- `<!-- not run: REASON -->`: the block is skipped, with its reason (a SLURM cluster, a build
  of minutes, a browser window). pytest's `-rs` lists each one.
- `<!-- needs: MODULE, ... -->`: the block is skipped when a Python module is missing here
  (CI's environment has them all).
- `<!-- file: NAME -->` above a ```toml block: the block is the file NAME that the guide asks
  the reader to save; it is written into the working directory before later blocks run.
- `<!-- prints: exactly -->`: the block's standard output is the indented block just after it
  (its sample output, where the output depends on nothing but the inputs), line for line: a
  sample that no longer holds fails.

Indented code blocks are never run: the two commands at the top of the front page (a full
build and the whole test suite) and sample outputs are indented. Each block's wall time is
printed; their sum is kept under 3 minutes on 2 busy cores by the pages' small sizes (a timing
is not an assertion).

The front page is held to its shape here too: one screen (at most 60 lines) that opens with what
fogplanes is, its picture and the two commands, in its first 20 lines.
"""

import importlib.util
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from conftest import README_SECONDS
from helpers import ROOT

README = ROOT / "README.md"
# The pages whose blocks run, in the order a reader takes them: the front page, the guide, then
# the reference pages with blocks (run or not), in the order the README held them before they
# moved to docs/ (no block of one uses another's files).
WALK = [README] + [ROOT / "docs" / name for name in (
    "guide.md", "python.md", "watching.md", "comparison_page.md", "results.md", "cluster.md",
    "mitsuba.md")]
RUN = ("sh", "bash", "python")
DIRECTIVE = re.compile(r"<!--\s*(not run|needs|file|prints)\s*:\s*(.*?)\s*-->")
# The longest any one block may take on a loaded machine before it counts as hung.
TIMEOUT_SECONDS = 240


@dataclass
class Block:
    page: str  # the file, relative to the repository's root
    language: str
    line: int  # of the opening fence, 1-based
    text: str
    directives: dict[str, str] = field(default_factory=dict)
    # The indented block just after the fenced one (a sample output), dedented; None if none.
    sample: str | None = None

    @property
    def id(self) -> str:
        return f"{self.page}:line{self.line}-{self.language}"

    @property
    def where(self) -> str:
        return f"{self.page} line {self.line}"


def blocks(markdown: str, page: str = "README.md") -> list[Block]:
    """The fenced blocks, each with the directives of the comment lines just above it."""
    found: list[Block] = []
    directives: dict[str, str] = {}
    lines = markdown.splitlines()
    i = 0
    while i < len(lines):
        stripped = lines[i].strip()
        if stripped.startswith("```"):
            info = stripped.removeprefix("```").split()
            start, body = i + 1, []
            i += 1
            while i < len(lines) and not lines[i].strip().startswith("```"):
                body.append(lines[i])
                i += 1
            assert i < len(lines), f"{page} line {start}: a fenced block is not closed"
            found.append(Block(page, info[0] if info else "", start, "\n".join(body) + "\n", directives,
                               indented_after(lines, i + 1)))
            directives = {}
        elif m := DIRECTIVE.fullmatch(stripped):
            directives = {**directives, m.group(1): m.group(2)}
        elif stripped:
            directives = {}
        i += 1
    return found


def indented_after(lines: list[str], i: int) -> str | None:
    """The indented block (four spaces) that follows line i after blank lines, dedented."""
    while i < len(lines) and not lines[i].strip():
        i += 1
    sample = []
    while i < len(lines) and (lines[i].startswith("    ") or not lines[i].strip()):
        sample.append(lines[i][4:])
        i += 1
    return "\n".join(sample).strip("\n") or None


def page_blocks(path: Path) -> list[Block]:
    return blocks(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))


BLOCKS = [b for path in WALK for b in page_blocks(path)]
FILES = [b for b in BLOCKS if "file" in b.directives]
RUNNABLE = [b for b in BLOCKS if b.language in RUN]


def test_the_walk_has_blocks_to_run_and_marks_the_rest():
    assert len(RUNNABLE) >= 10, [b.id for b in RUNNABLE]
    assert sum(b.page == "docs/guide.md" for b in RUNNABLE) >= 8, [b.id for b in RUNNABLE]
    assert FILES, "the guide's own scene is saved by a `<!-- file: NAME -->` block"
    unknown = sorted({(b.page, b.language) for b in BLOCKS if b.language not in {*RUN, "toml", "text", ""}})
    assert not unknown, f"blocks this test neither runs nor knows: {unknown}"
    for b in BLOCKS:
        assert "file" not in b.directives or b.language not in RUN, f"{b.id}: a file is data, not a command"
        assert "prints" not in b.directives or (b.directives["prints"] == "exactly" and b.sample), (
            f"{b.id}: `prints: exactly` needs the sample output indented just after the block")
        assert "not run" not in b.directives or b.directives["not run"], f"{b.id}: say why it is not run"


def test_every_page_with_blocks_to_run_is_walked():
    """A page of docs/ with a block to run (or marked not to run) that the walk leaves out would
    go untested."""
    for path in sorted((ROOT / "docs").rglob("*.md")):
        runnable = [b for b in page_blocks(path) if b.language in RUN]
        assert path in WALK or not runnable, f"{path.relative_to(ROOT)} has blocks to run: add it to WALK"


def test_the_front_page_fits_and_its_first_screen_says_what_it_is():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 60, f"README.md has {len(lines)} lines: the front page is one screen, at most 60"
    screen = "\n".join(lines[:20])
    assert lines[0] == "# fogplanes"
    assert re.search(r"^fogplanes renders .+", screen, re.M), "the sentence of what it is"
    assert re.search(r"^!\[[^\]]+\]\(docs/six_lights/render\.png\)", screen, re.M), "the benchmark's picture"
    assert "\n    cargo run --release -- render media_scenes/six_lights.toml\n" in screen
    assert "\n    cargo test --release\n" in screen


def test_the_two_commands_at_the_top_stay_unchanged_and_unrun():
    text = README.read_text(encoding="utf-8")
    top = text.split("\n---\n", 1)[0]
    assert "\n    cargo run --release -- render media_scenes/six_lights.toml\n" in top
    assert "\n    cargo test --release\n" in top
    assert "```" not in top, "the commands at the top are indented blocks, never run by this test"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    """One directory for every block, with the repository's inputs linked into it and the
    fresh binary on PATH; the files the guide asks the reader to save are written as their
    blocks come (see `test_block`)."""
    cli = Path(os.environ.get("FOGPLANES_CLI", ROOT / "target" / "release" / "fogplanes"))
    if not cli.is_file():
        pytest.fail(f"{cli} is missing: build the command line with `cargo build --release` first")
    work = tmp_path_factory.mktemp("readme")
    for name in ("media_scenes", "tests"):
        (work / name).symlink_to(ROOT / name, target_is_directory=True)
    bin_dir = tmp_path_factory.mktemp("bin")
    (bin_dir / "fogplanes").symlink_to(cli.resolve())
    work.joinpath(".path").write_text(os.pathsep.join([str(bin_dir), str(Path(sys.executable).parent)]))
    return work


def environment(work: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = work.joinpath(".path").read_text() + os.pathsep + env.get("PATH", "")
    env.pop("PYTHONPATH", None)
    return env


def missing_modules(block: Block) -> list[str]:
    names = [n.strip() for n in block.directives.get("needs", "").split(",") if n.strip()]
    return [n for n in names if importlib.util.find_spec(n) is None]


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.language in RUN or "file" in b.directives],
                         ids=lambda b: b.id)
def test_block(block: Block, workdir: Path, request):
    if "file" in block.directives:
        workdir.joinpath(block.directives["file"]).write_text(block.text, encoding="utf-8")
        return
    if "not run" in block.directives:
        pytest.skip(f"{block.where}: not run: {block.directives['not run']}")
    if missing := missing_modules(block):
        pytest.skip(f"{block.where}: needs {', '.join(missing)}, not installed here")
    if block.language == "python":
        script = workdir / f"{Path(block.page).stem}_line{block.line}.py"
        script.write_text(block.text, encoding="utf-8")
        command = [sys.executable, script.name]
    else:
        command = [shutil.which("bash") or "/bin/bash", "-e", "-c", block.text]
    started = time.monotonic()
    out, err = workdir / ".stdout", workdir / ".stderr"
    # Files rather than pipes, and a session of its own: a background process a block leaves
    # behind (a Dask scheduler) can hold neither the test nor the machine.
    with out.open("w") as stdout, err.open("w") as stderr:
        process = subprocess.Popen(command, cwd=workdir, env=environment(workdir), stdout=stdout,
                                   stderr=stderr, stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            code = process.wait(timeout=TIMEOUT_SECONDS)
        except subprocess.TimeoutExpired:
            code = None
        finally:
            try:
                os.killpg(process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            process.wait()
    result = subprocess.CompletedProcess(command, code, out.read_text(), err.read_text())
    if code is None:
        pytest.fail(f"{block.where}: still running after {TIMEOUT_SECONDS} s\n"
                    f"--- stdout\n{result.stdout}\n--- stderr\n{result.stderr}")
    seconds = time.monotonic() - started
    request.config.stash[README_SECONDS].append((block.where, seconds))
    print(f"{block.where} ({block.language}): {seconds:.1f} s\n{result.stdout}")
    assert result.returncode == 0, (
        f"{block.where} ({block.language}) exited {result.returncode}\n"
        f"--- block\n{block.text}--- stdout\n{result.stdout}\n--- stderr\n{result.stderr}"
    )
    if "prints" in block.directives:
        assert result.stdout.strip("\n") == block.sample, (
            f"{block.where}: the page's sample output no longer holds\n--- the page\n{block.sample}\n"
            f"--- printed\n{result.stdout}")
