"""Tests of the ``aacmm-pin`` command layer: --version, --help, handlers, the lazy package import."""

from __future__ import annotations

import argparse
import ast
import importlib
import importlib.metadata
import json
import os
import subprocess
import sys
from collections.abc import Iterator

import pytest

import aacmm_pin
from aacmm_pin import cli
from tests.helpers import ENV, ROOT

HEAVY = ("numpy", "pinocchio", "yourdfpy", "scipy", "matplotlib")
COMMANDS = {("axes",), ("simulate",), ("predict",), ("identify",), ("discover",), ("validate",),
            ("uncertainty",), ("plan",), ("demo",), ("view",), ("acquire",), ("fake-devices",),
            ("import-points",),
            ("iso10360", "spat"), ("iso10360", "sphere"), ("iso10360", "ldia"),
            ("iso10360", "euni")}


def leaves(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
           ) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Yield (command words, parser) of every leaf subcommand below ``parser``."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield path, parser
        return
    for name, child in subs[0].choices.items():
        yield from leaves(child, (*path, name))


def squeeze(text: str) -> str:
    """Text without whitespace (help lines wrap anywhere, also at hyphens)."""
    return "".join(text.split())


def test_version_prints_program_and_version(capsys):
    """``--version`` prints ``aacmm-pin <version>``, exits 0, and agrees with ``__version__``."""
    with pytest.raises(SystemExit) as info:
        cli.main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out == f"aacmm-pin {aacmm_pin.__version__}\n"
    assert cli.version() == importlib.metadata.version("aacmm_pin") == aacmm_pin.__version__


def test_version_falls_back_to_the_package(monkeypatch):
    """Without installed metadata, the version is the package's ``__version__``."""
    def missing(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert cli.version() == aacmm_pin.__version__


def test_every_command_has_a_handler():
    """Every subcommand (and every iso10360 figure) is registered and sets a callable handler."""
    found = dict(leaves(cli.build_parser()))
    assert set(found) == COMMANDS
    for path, parser in found.items():
        assert callable(parser.get_default("handler")), path


def test_the_command_index_lists_every_command_in_order():
    """``cli.COMMANDS`` (what a command line's first word builds alone) is the full parser's list."""
    subs = [a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    assert list(subs[0].choices) == list(cli.COMMANDS)


@pytest.mark.parametrize("command", list(cli.COMMANDS))
def test_a_command_built_alone_parses_and_helps_as_in_the_full_parser(command):
    """``build_parser(command)`` gives the command the same usage, help, actions and defaults.

    Only the first word of a command line selects (``aacmm-pin identify ...``); a word that is no
    command builds them all, so argparse names every choice in its error.
    """
    def described(action: argparse.Action) -> tuple:
        kind = getattr(action.type, "__qualname__", action.type)  # a closure: one per build
        return action.dest, action.default, kind, action.choices, action.option_strings

    def parsers(parser: argparse.ArgumentParser) -> dict[tuple[str, ...], argparse.ArgumentParser]:
        return {path: leaf for path, leaf in leaves(parser) if path[0] == command}

    full, alone = parsers(cli.build_parser()), parsers(cli.build_parser(command))
    assert list(full) == list(alone) and full
    for path, parser in full.items():
        assert alone[path].format_help() == parser.format_help(), path
        assert [described(a) for a in alone[path]._actions] == \
            [described(a) for a in parser._actions], path
        handlers = alone[path].get_default("handler"), parser.get_default("handler")
        assert handlers[0].__qualname__ == handlers[1].__qualname__  # closures: one per build
    assert dict(leaves(cli.build_parser("identfy"))).keys() == COMMANDS


@pytest.mark.parametrize("path", sorted(COMMANDS), ids=" ".join)
def test_help_shows_every_default(path, capsys):
    """``--help`` of each subcommand exits 0, documents every argument and shows its defaults."""
    parser = dict(leaves(cli.build_parser()))[path]
    with pytest.raises(SystemExit) as info:
        cli.main([*path, "--help"])
    assert info.value.code == 0
    text = squeeze(capsys.readouterr().out)
    assert squeeze(f"usage: aacmm-pin {' '.join(path)}") in text
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
            continue
        assert action.help, f"{path}: {action.dest} has no help"
        default = action.default
        if action.option_strings and default not in (None, False, [], argparse.SUPPRESS):
            assert squeeze(f"(default: {default})") in text, (path, action.dest)


def test_effect_names_are_the_simulators():
    """The CLI offers the simulator's effects and defaults (one list, in aacmm_pin.units)."""
    from aacmm_pin.analyses.simulate import DEFAULT_EFFECTS, SimulationConfig

    assert SimulationConfig().effects == DEFAULT_EFFECTS
    assert cli.build_parser().parse_args(["simulate", "out"]).effects == ",".join(DEFAULT_EFFECTS)


def test_bad_input_is_a_message_and_status_2(tmp_path, capsys):
    """An unreadable input file ends in one error line naming the command, exit status 2."""
    assert cli.main(["validate", str(tmp_path / "missing"), str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("aacmm-pin validate: error: ") and "missing" in err
    assert "Traceback" not in err


def test_building_the_parser_imports_no_heavy_module():
    """``import aacmm_pin.cli`` and building (and formatting) every parser import no heavy module."""
    code = (
        "import sys, json\n"
        "import aacmm_pin, aacmm_pin.cli\n"
        "parser = aacmm_pin.cli.build_parser()\n"
        "parser.format_help()\n"
        "parser.parse_args(['iso10360', 'sphere', 'p.csv', '--diameter-mm', '25'])\n"
        "print(json.dumps([aacmm_pin.__version__, sorted(m.split('.')[0] for m in sys.modules)]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV,
                         check=True, timeout=120).stdout
    version, modules = json.loads(out)
    assert version == aacmm_pin.__version__
    assert [m for m in HEAVY if m in modules] == []
    assert "aacmm_pin" in modules


BLAS_PROBE = (
    "import json, os, sys\n"
    "from aacmm_pin.cli import one_blas_thread_at_start\n"
    "did = one_blas_thread_at_start()\n"
    "import numpy, scipy.linalg\n"
    "from threadpoolctl import threadpool_info\n"
    "print(json.dumps([did, sorted({i['num_threads'] for i in threadpool_info()\n"
    "                               if i['internal_api'] == 'openblas'})]))\n")


@pytest.mark.parametrize("user, did, threads", [
    ({}, True, {1}),  # nothing set: numpy's and scipy's OpenBLAS start with one thread each
    ({"OPENBLAS_NUM_THREADS": "2"}, False, {2}),  # the user's setting stands
    ({"OMP_NUM_THREADS": "2"}, False, {2}),
])
def test_the_program_starts_openblas_with_one_thread_unless_the_user_set_threads(user, did, threads):
    """Before numpy is imported, the command line starts OpenBLAS with one thread; a user's
    thread setting stands (the machine has 2 cores: 2 threads show it was not overridden)."""
    env = {k: v for k, v in ENV.items() if k not in cli.BLAS_THREAD_VARIABLES} | user
    out = subprocess.run([sys.executable, "-c", BLAS_PROBE], capture_output=True, text=True,
                         env=env, check=True, timeout=120).stdout
    got_did, got_threads = json.loads(out)
    assert got_did is did
    if (os.cpu_count() or 1) >= 2 or did:
        assert set(got_threads) == threads


def test_blas_threads_are_left_alone_once_numpy_is_loaded(monkeypatch):
    """In a process that imported numpy already (the Python API, tests), nothing is changed."""
    for name in cli.BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert cli.one_blas_thread_at_start() is False
    assert not any(name in os.environ for name in cli.BLAS_THREAD_VARIABLES)


def test_python_m_runs_the_command():
    """``python -m aacmm_pin --version`` runs ``main`` and prints the version."""
    done = subprocess.run([sys.executable, "-m", "aacmm_pin", "--version"], capture_output=True,
                          text=True, env=ENV, timeout=120)
    assert done.returncode == 0 and done.stdout == f"aacmm-pin {aacmm_pin.__version__}\n"


def test_lazy_package_exports_every_public_name():
    """Every name of ``__all__`` resolves to the object its module defines and is in ``dir()``."""
    assert set(aacmm_pin.__all__) <= set(dir(aacmm_pin))
    for name in aacmm_pin.__all__:
        module = importlib.import_module(f"aacmm_pin.{aacmm_pin._MODULE_OF[name]}")
        assert getattr(aacmm_pin, name) is getattr(module, name), name
    assert aacmm_pin.model.parameters is importlib.import_module("aacmm_pin.model.parameters")
    with pytest.raises(AttributeError, match="no_such_name"):
        aacmm_pin.no_such_name
    from aacmm_pin import identify

    assert identify is aacmm_pin.identify


def test_lazy_table_matches_the_type_checking_imports():
    """The lazy table and the ``if TYPE_CHECKING:`` imports (for mypy and IDEs) list the same names."""
    tree = ast.parse((ROOT / "aacmm_pin" / "__init__.py").read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If)
                 and getattr(n.test, "id", None) == "TYPE_CHECKING")
    imported = {(node.module.removeprefix("aacmm_pin."), alias.name)
                for node in block.body if isinstance(node, ast.ImportFrom) and node.module
                for alias in node.names}
    assert imported == {(module, name) for name, module in aacmm_pin._MODULE_OF.items()}
    assert {name for _, name in imported} == set(aacmm_pin.__all__)


def test_axes_lists_readout_order_of_a_robot(capsys):
    """`aacmm-pin axes ur5` names the 6 readout columns in chain order and the error frames."""
    assert cli.main(["axes", "ur5"]) == 0
    out = capsys.readouterr().out
    assert "6 axes" in out and "q6_deg  joint A6" in out and "q7_deg" not in out
    assert "error frames (26)" in out
