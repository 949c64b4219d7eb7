"""The README runs as printed: every ```sh, ```bash and ```python block, in order.

All blocks run in one temporary working directory, so that a block can use what an earlier one
wrote, as a reader working through the README would; the directory holds links to the
repository's `media_scenes` and `tests` (the README's paths are relative to the clone's root).
A shell block runs with bash (`set -e`: its first failing command fails it), with the command
line built by `cargo build --release` first on PATH as `fogplanes` (FOGPLANES_CLI overrides
its path) and this Python's environment next (so `python3` and `dask` are the venv's); a
Python block runs as a script of its own in this Python.

Comment lines just above a block's opening fence steer it:

- `<!-- not run: REASON -->`: the block is skipped, with its reason (a SLURM cluster, a build
  of minutes, a browser window). pytest's `-rs` lists each one.
- `<!-- needs: MODULE, ... -->`: the block is skipped when a Python module is missing here
  (CI's environment has them all).
- `<!-- file: NAME -->` above a ```toml block: the block is the file NAME that the README asks
  the reader to save; it is written into the working directory before later blocks run.

Indented code blocks are never run: the two commands at the top (a full build and the whole
test suite) and sample outputs are indented. Each block's wall time is printed; their sum is
kept under 3 minutes on 2 busy cores by the README's small sizes (a timing is not an
assertion).
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
RUN = ("sh", "bash", "python")
DIRECTIVE = re.compile(r"<!--\s*(not run|needs|file)\s*:\s*(.*?)\s*-->")
# The longest any one block may take on a loaded machine before it counts as hung.
TIMEOUT_SECONDS = 240


@dataclass
class Block:
    language: str
    line: int  # of the opening fence, 1-based
    text: str
    directives: dict[str, str] = field(default_factory=dict)

    @property
    def id(self) -> str:
        return f"line{self.line}-{self.language}"


def blocks(markdown: str) -> list[Block]:
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
            assert i < len(lines), f"README.md line {start}: a fenced block is not closed"
            found.append(Block(info[0] if info else "", start, "\n".join(body) + "\n", directives))
            directives = {}
        elif m := DIRECTIVE.fullmatch(stripped):
            directives = {**directives, m.group(1): m.group(2)}
        elif stripped:
            directives = {}
        i += 1
    return found


BLOCKS = blocks(README.read_text(encoding="utf-8"))
FILES = [b for b in BLOCKS if "file" in b.directives]
RUNNABLE = [b for b in BLOCKS if b.language in RUN]


def test_the_readme_has_blocks_to_run_and_marks_the_rest():
    assert len(RUNNABLE) >= 10, [b.id for b in RUNNABLE]
    assert FILES, "the README's own scene is saved by a `<!-- file: NAME -->` block"
    unknown = sorted({b.language for b in BLOCKS} - {*RUN, "toml", "text", ""})
    assert not unknown, f"README.md has blocks this test neither runs nor knows: {unknown}"
    for b in BLOCKS:
        assert "file" not in b.directives or b.language not in RUN, f"{b.id}: a file is data, not a command"
        assert "not run" not in b.directives or b.directives["not run"], f"{b.id}: say why it is not run"


def test_the_two_commands_at_the_top_stay_unchanged_and_unrun():
    text = README.read_text(encoding="utf-8")
    top = text.split("\n---\n", 1)[0]
    assert "\n    cargo run --release -- render media_scenes/six_lights.toml\n" in top
    assert "\n    cargo test --release\n" in top
    assert "```" not in top, "the commands at the top are indented blocks, never run by this test"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    """One directory for every block, with the repository's inputs linked into it and the
    fresh binary on PATH; the files the README asks the reader to save are written as their
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
        pytest.skip(f"README.md line {block.line}: not run: {block.directives['not run']}")
    if missing := missing_modules(block):
        pytest.skip(f"README.md line {block.line}: needs {', '.join(missing)}, not installed here")
    if block.language == "python":
        script = workdir / f"readme_line{block.line}.py"
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
        pytest.fail(f"README.md line {block.line}: still running after {TIMEOUT_SECONDS} s\n"
                    f"--- stdout\n{result.stdout}\n--- stderr\n{result.stderr}")
    seconds = time.monotonic() - started
    request.config.stash[README_SECONDS].append((block.line, seconds))
    print(f"README.md line {block.line} ({block.language}): {seconds:.1f} s\n{result.stdout}")
    assert result.returncode == 0, (
        f"README.md line {block.line} ({block.language}) exited {result.returncode}\n"
        f"--- block\n{block.text}--- stdout\n{result.stdout}\n--- stderr\n{result.stderr}"
    )
