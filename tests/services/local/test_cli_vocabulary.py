"""One vocabulary across every `graspscape` subcommand (shared/cli_args.py): the same flag for
the same thing, the object as a positional, angles in degrees, --data-dir where a command reads
the store, help on every option, and validation errors as one line naming flag and unit."""

from __future__ import annotations

import argparse
import re

import pytest
from graspscape.services.local.cli import build_parser, main


def _commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
              ) -> list[tuple[str, argparse.ArgumentParser]]:
    found = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found.append((" ".join((*path, name)), sub))
                found += _commands(sub, (*path, name))
    return found


COMMANDS = dict(_commands(build_parser()))
LEAVES = {name: p for name, p in COMMANDS.items()
          if not any(isinstance(a, argparse._SubParsersAction) for a in p._actions)}
# Each thing's one spelling, where a command has it.
CANONICAL = {"procs": "--procs", "gripper": "--gripper", "data_dir": "--data-dir",
             "database_url": "--database-url", "dtheta": "--dtheta", "r_min": "--r-min",
             "r_max": "--r-max", "dr": "--dr", "rolls": "--rolls", "levels": "--levels",
             "mass": "--mass", "friction": "--friction", "scale": "--scale", "out": "--out",
             "url": "--url"}
READS_THE_STORE = ("serve", "db upgrade", "db current", "explore", "atlas", "map show",
                   "map export", "map run")
ANGLES = ("theta", "phi", "roll", "dtheta", "phi0")


def _visible(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions
            if a.help != argparse.SUPPRESS and not isinstance(a, argparse._HelpAction)
            and not isinstance(a, argparse._SubParsersAction)]


def test_the_walk_finds_every_subcommand() -> None:
    assert {"explore", "map run", "map show", "map export", "eval-pose", "render-pose",
            "worker", "serve", "atlas", "gripper check", "submit", "status", "best",
            "export", "compare-policies", "db upgrade"} <= set(LEAVES)


@pytest.mark.parametrize("command", sorted(LEAVES))
def test_vocabulary(command: str) -> None:
    parser = LEAVES[command]
    for action in _visible(parser):
        name = action.option_strings[-1] if action.option_strings else action.dest
        assert action.help and action.help.strip(), f"{command} {name}: no help"
        assert not re.search(r"\brad\b|radian", action.help), f"{command} {name}: radians"
        if action.dest in CANONICAL and action.option_strings:  # a command's subject: positional
            assert CANONICAL[action.dest] in action.option_strings, (command, name)
        if action.dest in ANGLES:
            assert "degrees" in action.help, f"{command} {name}: angle without its unit"
        assert not {"--processes", "--db", "--object", "--objects"} & set(
            action.option_strings), f"{command}: an earlier spelling shown"
    dests = {a.dest for a in parser._actions}
    if "object" in dests:  # the object is a positional wherever a command takes one
        assert any(a.dest == "object" and not a.option_strings for a in parser._actions)
    if command in READS_THE_STORE:
        assert "data_dir" in dests, f"{command}: no --data-dir"


@pytest.mark.parametrize(("argv", "flag", "unit"), [
    (["explore", "mug", "--dtheta", "0.35"], "--dtheta", "degrees"),
    (["explore", "mug", "--dtheta", "abc"], "--dtheta", "degrees"),
    (["eval-pose", "--theta", "200", "--phi", "0"], "--theta", "degrees"),
    (["map", "run", "mug", "--r-max", "-1"], "--r-max", " m"),
    (["explore", "mug", "--mass", "0"], "--mass", "kg"),
    (["explore", "mug", "--procs", "0"], "--procs", "processes"),
])
def test_a_bad_value_is_one_line_naming_flag_and_unit(argv, flag, unit, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(argv)
    assert exited.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith(f"graspscape {argv[0]}") and f"argument {flag}" in last, last
    assert unit in last, last


def test_earlier_spellings_still_parse() -> None:
    parser = build_parser()
    args = parser.parse_args(["map", "run", "--object", "mug", "--processes", "2"])
    from graspscape.shared.cli_args import resolve_object

    resolve_object(parser, args)
    assert (args.object, args.procs) == ("mug", 2)
    args = parser.parse_args(["eval-pose", "--theta", "90", "--phi", "45"])
    resolve_object(parser, args)
    assert (args.object, args.theta, args.phi) == ("sphere", 90.0, 45.0)


def test_draw_engines_one_flag_wherever_a_spec_is_made() -> None:
    """explore and submit both make an exploration spec: the same --draw-engines, parsed to
    the spec's engine names, which are the engines the flag knows."""
    import typing

    from graspscape.shared.cli_args import ENGINES
    from graspscape.shared.specs.sim import EngineName

    assert typing.get_args(EngineName) == ENGINES
    parser = build_parser()
    for command in ("explore", "submit"):
        args = parser.parse_args([command, "mug", "--draw-engines", " pybullet, mujoco"])
        assert args.draw_engines == ("pybullet", "mujoco")
        assert parser.parse_args([command, "mug"]).draw_engines is None


@pytest.mark.parametrize("engines", ["bullet", "pybullet,pybullet", ","])
def test_bad_draw_engines_are_one_line(engines: str, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["submit", "mug", "--draw-engines", engines])
    assert exited.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "argument --draw-engines" in last and "pybullet, mujoco" in last, last
