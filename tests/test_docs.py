"""Every ``bash`` and ``python`` block of the README and of docs/ runs, and the README stays short.

The blocks run as a user runs them: a document's blocks in page order, in a fresh temporary folder
of its own that is not the repository and holds none of its files (no ``urdf/``, no ``aacmm_pin/``),
with the *installed* ``aacmm-pin`` console script and the ``python`` of the environment running the
tests (nothing is installed here: ``.ci/run`` installs the package with the README's line first; on
a developer's machine install the checkout, ``pip install -e .``). The installed package must be
this checkout's (the same source files), else the blocks fail at once, naming both. A shell line
runs as a command; a Python block is saved as a file of its own and run with ``python FILE`` (each
block is self-contained, as a reader would paste it into a file). The docs name the shared data as
``../shared`` (the project's folder ``shared/`` beside a checkout): the fresh folder's parent holds
a link ``shared`` to it, and nothing else of the repository is reachable. A comment just before a
block changes when it runs:

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

import functools
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.helpers import ROOT

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
    """A document's fresh folder (``base/work``, beside ``base/shared``) and the blocks run in it."""

    base: Path
    done: set[int] = field(default_factory=set)

    @property
    def work(self) -> Path:
        """The folder the blocks run in (the reader's own folder)."""
        return self.base / "work"


_SESSIONS: dict[Path, Session] = {}
REPOSITORY_FILES = ("urdf", "aacmm_pin", "pyproject.toml", "tests", "docs", "README.md", ".git")
"""Files of the repository that a block's folder must not hold (it runs as a user's would)."""


def _session(doc: Path, factory: pytest.TempPathFactory) -> Session:
    if doc not in _SESSIONS:
        base = factory.mktemp(doc.stem)
        (base / "shared").symlink_to(SHARED, target_is_directory=True)
        (base / "work").mkdir()
        (base / "blocks").mkdir()
        _SESSIONS[doc] = Session(base)
    return _SESSIONS[doc]


def _environment() -> dict[str, str]:
    """The tests' environment without this checkout on ``PYTHONPATH``, the environment's scripts first.

    ``aacmm-pin`` and ``python`` are then the installed console script and the interpreter running
    the tests (its virtual environment's, in CI the one the README's install line filled).
    """
    env = dict(os.environ)
    kept = [entry for entry in env.pop("PYTHONPATH", "").split(os.pathsep)
            if entry and not _inside(Path(entry), ROOT)]
    if kept:
        env["PYTHONPATH"] = os.pathsep.join(kept)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    return env


def _inside(path: Path, folder: Path) -> bool:
    resolved, top = path.resolve(), folder.resolve()
    return resolved == top or top in resolved.parents


def _digest(package: Path) -> dict[str, str]:
    return {str(f.relative_to(package)): hashlib.sha1(f.read_bytes()).hexdigest()
            for f in sorted(package.rglob("*.py"))}


@functools.cache
def installed() -> tuple[Path, Path]:
    """Return the installed ``aacmm-pin`` script and ``aacmm_pin`` package folder, checked.

    Raises:
        AssertionError: if the environment has no ``aacmm-pin`` script, or its package is not this
            checkout's (the same ``.py`` files, byte for byte).
    """
    env = _environment()
    script = shutil.which("aacmm-pin", path=env["PATH"])
    assert script, (f"no installed aacmm-pin on PATH ({Path(sys.executable).parent} first): install "
                    f"this checkout in the environment running the tests (pip install -e {ROOT})")
    probe = subprocess.run([sys.executable, "-c", "import aacmm_pin; print(aacmm_pin.__file__)"],
                           cwd=tempfile.gettempdir(), env=env, capture_output=True, text=True)
    assert probe.returncode == 0, f"the environment cannot import aacmm_pin:\n{probe.stderr}"
    package = Path(probe.stdout.strip()).parent
    ours, theirs = _digest(ROOT / "aacmm_pin"), _digest(package)
    changed = sorted(name for name in ours if theirs.get(name) != ours[name])
    assert not changed, (f"the installed aacmm_pin ({package}) is not this checkout's ({ROOT}): "
                         f"{len(changed)} files differ ({', '.join(changed[:5])}); install this "
                         f"checkout (pip install -e {ROOT}) in {Path(sys.executable).parent.parent}")
    return Path(script), package


def assert_fresh(work: Path) -> None:
    """Assert a block's folder is a user's: outside the repository, without repository files."""
    assert not _inside(work, ROOT), f"{work} is inside the repository {ROOT}"
    present = [name for name in REPOSITORY_FILES if (work / name).exists()]
    assert not present, f"{work} holds repository files: {present}"
    beside = sorted(p.name for p in work.parent.iterdir())
    assert beside == ["blocks", "shared", "work"], f"{work.parent} holds {beside}"


def _run(block: Block, session: Session) -> None:
    installed()
    assert_fresh(session.work)
    env = _environment()
    timeout = 1800 if block.slow else 300
    if block.lang == "python":
        # saved as a file, as a reader would (a script's main guard matters to multiprocessing)
        script = session.base / "blocks" / f"{block.doc.stem}_{block.line}.py"
        script.write_text(block.text + "\n")
        runs = [["python", str(script)]]
    else:
        runs = [["bash", "-euo", "pipefail", "-c", line] for line in shell_lines(block.text)]
    printed = ""
    for argv in runs:
        proc = subprocess.run(argv, cwd=session.work, env=env, capture_output=True, text=True,
                              timeout=timeout)
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
            _run(earlier, session)
            session.done.add(earlier.line)
    if block.line not in session.done:
        _run(block, session)
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


def test_blocks_run_where_a_user_would(tmp_path_factory: pytest.TempPathFactory) -> None:
    """A block's folder holds no repository file (no urdf/, no aacmm_pin/, none beside it), its
    ``aacmm-pin`` is the installed script, its ``python`` imports the installed package (not this
    checkout through the folder or PYTHONPATH) and ``../shared`` is the shared data; a folder inside
    the repository, or one holding a repository file, is refused."""
    script, package = installed()
    doc = ROOT / "fresh-folder-probe.md"
    lines = ["test ! -e urdf && test ! -e aacmm_pin && test ! -e ../urdf && test ! -e ../aacmm_pin",
             "command -v aacmm-pin",
             "python -c 'import aacmm_pin, os; print(os.path.dirname(aacmm_pin.__file__))'"]
    prints = [str(script), str(package)]
    if SHARED.is_dir():
        lines.append("test -f ../shared/sample-campaign/spat.csv && echo shared-reached")
        prints.append("shared-reached")
    _run(Block(doc, 1, "bash", "", "\n".join(lines), tuple(prints)), _session(doc, tmp_path_factory))
    with pytest.raises(AssertionError, match="inside the repository"):
        assert_fresh(ROOT / "docs")
    base = tmp_path_factory.mktemp("not-fresh")
    for name in ("blocks", "shared", "work/urdf"):
        (base / name).mkdir(parents=True)
    with pytest.raises(AssertionError, match=r"repository files: \['urdf'\]"):
        assert_fresh(base / "work")
