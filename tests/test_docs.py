"""Every ``bash`` and ``python`` block of the README and of docs/ runs, and the README stays short.

Blocks run in a temporary folder per document, in the document's order: a shell line as a command
(``aacmm-pin`` and ``python`` are this checkout's, whatever is installed), a Python block in a
process of its own (each block is self-contained, as a reader would paste it). ``../shared`` and
``urdf/`` resolve as from the repository's folder. A comment just before a block changes when it
runs:

* ``<!-- slow -->``: only under ``pytest -m slow`` (long commands);
* ``<!-- needs: hardware -->``: never (serial ports);
* ``<!-- ci -->``: install, test and docs-build commands, which ``.ci/run`` runs: checked to be there;
* ``<!-- pending: COMMAND -->``: a subcommand another change adds; skipped while the CLI lacks it and
  a failure once it has it (the marker must then go).

A comment just after a block, ``<!-- prints: TEXT | TEXT ... -->``, states what its output holds (each
TEXT, runs of spaces counting as one): the numbers the text quotes are checked where they are made.

A block runs after the earlier blocks of its document that it may depend on (the fast ones for a
fast block, all of them for a slow one), so ``-k`` can pick any one.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.helpers import ENV, ROOT

README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
SHARED = ROOT.parent / "shared"
README_LIMIT = 300  # lines (issue 26: about 250, at most 300)
FENCE = re.compile(r"^```(\S*)\s*$")
MARK = re.compile(r"^<!--\s*(.*?)\s*-->\s*$")
PRINTS = re.compile(r"^<!--\s*prints:\s*(.*?)\s*-->\s*$")


@dataclass(frozen=True)
class Block:
    """One fenced block: its document, first line (1-based), language, marker and text."""

    doc: Path
    line: int
    lang: str
    mark: str
    text: str
    prints: tuple[str, ...] = ()

    @property
    def id(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"

    @property
    def slow(self) -> bool:
        return self.mark == "slow"

    @property
    def runs(self) -> bool:
        return self.mark in ("", "slow")


def blocks(doc: Path) -> list[Block]:
    """Return the ``bash`` and ``python`` blocks of a Markdown file, with the marker before each."""
    lines = doc.read_text().splitlines()
    out: list[Block] = []
    k = 0
    while k < len(lines):
        fence = FENCE.match(lines[k])
        if not fence:
            k += 1
            continue
        end = next(j for j in range(k + 1, len(lines)) if lines[j].startswith("```"))
        before = next((lines[j] for j in range(k - 1, -1, -1) if lines[j].strip()), "")
        after = next((lines[j] for j in range(end + 1, len(lines)) if lines[j].strip()), "")
        mark = None if PRINTS.match(before) else MARK.match(before)
        prints = PRINTS.match(after)
        if fence.group(1) in ("bash", "python"):
            out.append(Block(doc, k + 1, fence.group(1), mark.group(1) if mark else "",
                             "\n".join(lines[k + 1:end]),
                             tuple(t.strip() for t in prints.group(1).split("|")) if prints else ()))
        k = end + 1
    return out


ALL = [b for doc in [README, *DOCS] for b in blocks(doc)]


def shell_lines(text: str) -> list[str]:
    """Return the commands of a bash block: continuation lines joined, comments and blanks left out."""
    out: list[str] = []
    pending = ""
    for raw in text.splitlines():
        line = pending + raw.strip()
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        if line and not line.startswith("#"):
            out.append(line)
    return out


@dataclass
class Session:
    """A document's temporary folder and the blocks already run in it."""

    work: Path
    done: set[int] = field(default_factory=set)


_SESSIONS: dict[Path, Session] = {}


def _session(doc: Path, factory: pytest.TempPathFactory) -> Session:
    if doc not in _SESSIONS:
        base = factory.mktemp(doc.stem)
        (base / "shared").symlink_to(SHARED, target_is_directory=True)
        work = base / "repo"
        work.mkdir()
        (work / "urdf").symlink_to(ROOT / "urdf", target_is_directory=True)
        _SESSIONS[doc] = Session(work)
    return _SESSIONS[doc]


def _run(block: Block, work: Path) -> None:
    exe = sys.executable
    env = {**ENV, "PATH": str(Path(exe).parent) + os.pathsep + os.environ.get("PATH", "")}
    timeout = 1800 if block.slow else 300
    if block.lang == "python":
        runs = [[exe, "-c", block.text]]
    else:
        # the checkout's CLI and interpreter, whatever an installed console script points to
        prelude = f'aacmm-pin() {{ "{exe}" -m aacmm_pin "$@"; }}; python() {{ "{exe}" "$@"; }}; '
        runs = [["bash", "-euo", "pipefail", "-c", prelude + line] for line in shell_lines(block.text)]
    printed = ""
    for argv in runs:
        proc = subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True, timeout=timeout)
        assert proc.returncode == 0, (
            f"{block.id}: {argv[-1][-300:]!r} exited {proc.returncode}\n"
            f"stdout: {proc.stdout[-2000:]}\nstderr: {proc.stderr[-2000:]}")
        printed += proc.stdout
    flat = re.sub(r"[ \t]+", " ", printed)
    for text in block.prints:
        assert re.sub(r"\s+", " ", text) in flat, f"{block.id} does not print {text!r}:\n{printed[-3000:]}"


def _subcommands() -> set[str]:
    from aacmm_pin.cli import build_parser

    parser = build_parser()
    return {name for action in parser._subparsers._group_actions  # type: ignore[union-attr]
            for name in getattr(action, "choices", {})}


def _param(block: Block) -> object:
    marks = [pytest.mark.slow] if block.slow else []
    return pytest.param(block, id=block.id, marks=marks)


@pytest.mark.parametrize("block", [_param(b) for b in ALL if b.mark != "ci"])
def test_block_runs(block: Block, tmp_path_factory: pytest.TempPathFactory) -> None:
    """The block runs (exit status 0 for every shell line and Python block)."""
    if block.mark.startswith("needs:"):
        pytest.skip(f"{block.id} {block.mark}")
    if block.mark.startswith("pending:"):
        command = block.mark.split(":", 1)[1].strip()
        assert command not in _subcommands(), \
            f"{block.id}: aacmm-pin {command} exists now: remove the '<!-- {block.mark} -->' marker"
        pytest.skip(f"{block.id}: aacmm-pin {command} is not in this build")
    assert block.runs, f"{block.id}: unknown marker <!-- {block.mark} -->"
    if not SHARED.is_dir() and "../shared" in block.text:
        pytest.skip(f"{SHARED} not found")
    session = _session(block.doc, tmp_path_factory)
    for earlier in ALL:
        if (earlier.doc == block.doc and earlier.line < block.line and earlier.runs
                and earlier.line not in session.done and (block.slow or not earlier.slow)):
            _run(earlier, session.work)
            session.done.add(earlier.line)
    if block.line not in session.done:
        _run(block, session.work)
        session.done.add(block.line)


def _two_commands() -> list[str]:
    text = README.read_text()
    section = text[text.index("## Two commands"):]
    block = section[section.index("```bash\n") + 8:]
    return block[:block.index("```")].strip().splitlines()


def test_ci_blocks_are_run_by_ci() -> None:
    """A block marked ``ci`` is the README's two commands or lines ``.ci/run`` runs as written."""
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    two = _two_commands()
    assert len(two) == 2 and "pip install" in two[0] and "pytest" in two[1], two
    marked = [b for b in ALL if b.mark == "ci"]
    assert marked
    for block in marked:
        for line in shell_lines(block.text):
            assert line in two or any(c.strip() == line for c in ci), f"{block.id}: {line!r} not in .ci/run"


def test_readme_is_short_and_leads_to_every_page() -> None:
    """The README is at most 300 lines and links every page of docs/."""
    text = README.read_text()
    assert len(text.splitlines()) <= README_LIMIT
    for page in DOCS:
        if page.stem != "index":
            assert f"docs/{page.name}" in text, f"the README does not link docs/{page.name}"


def test_markers_are_known() -> None:
    """Every marker is one this test knows (a typo would otherwise run or skip a block silently)."""
    for block in ALL:
        assert block.mark in ("", "slow", "ci") or re.fullmatch(r"(needs|pending): \S.*", block.mark), \
            f"{block.id}: <!-- {block.mark} -->"


def test_api_reference_lists_every_public_name() -> None:
    """docs/api.md's tables name every public name of ``aacmm_pin`` at the module defining it."""
    import aacmm_pin

    text = (ROOT / "docs" / "api.md").read_text()
    listed = set(re.findall(r"^   aacmm_pin\.([\w.]+)$", text, flags=re.M))
    for module, names in aacmm_pin._PUBLIC.items():
        for name in names:
            assert f"{module}.{name}" in listed, f"docs/api.md does not list aacmm_pin.{name}"
