"""Every option of a command that computes something is an argument of the API function
the command calls, under the name its table gives (``*_OPTIONS`` in ``cli/``: API keyword
-> option, used to name the option in an error about the argument); the options left are
presentation only (where to write, JSON, figures). The command line thus has no knob the
Python API lacks, and no table names an option or an argument that does not exist."""

from __future__ import annotations

import importlib
import inspect

import click
import pytest
from typer.main import get_command

from maglev_match import api
from maglev_match.cli import app
from maglev_match.cli.common import PARAMETER_SET_OPTIONS

#: options about presenting or keeping the answer, not about what is computed
PRESENTATION = {"--json", "--out", "--plot", "--keep-tiles", "--iso", "--iso-curve"}
#: where and how `explore` serves its page (the computations are the API's, as in `index`)
PRESENTATION |= {"--port", "--host", "--no-browser"}

#: command -> (its option tables in cli/, the API functions it calls)
COMMANDS = {
    "stability": (["stability.STABILITY_OPTIONS"], ["stability"]),
    "root-locus": (["stability.ROOT_LOCUS_OPTIONS"], ["root_locus"]),
    "hopf": (["hopf.HOPF_OPTIONS"], ["hopf_points"]),
    "hopf-curve": (["hopf.HOPF_CURVE_OPTIONS"], ["hopf_curve"]),
    "cycles": (["cycles.CYCLES_OPTIONS", "cycles.HOPF_SEARCH_OPTIONS"],
               ["cycle_study"]),
    "cycle-curve": (["cycle_curve.CYCLE_CURVE_OPTIONS"], ["cycle_curve"]),
    "iso-curve": (["iso_curve.ISO_CURVE_OPTIONS"], ["iso_curve", "restart_iso_curve"]),
    "simulate": (["simulate.SIMULATE_OPTIONS"], ["simulate", "simulate_over_spans"]),
    "speed": (["speed.SPEED_OPTIONS"], ["speed_sweep", "speed_map"]),
    "index": (["index.INDEX_OPTIONS", "design.SCATTER_OPTIONS"],
              ["matching_index", "index_spread"]),
    "map": (["index.MAP_OPTIONS"], ["design_map"]),
    "explore": (["explore.EXPLORE_OPTIONS"], ["matching_index", "stability"]),
    "sensitivity": (["design.SENSITIVITY_OPTIONS", "design.SCATTER_OPTIONS"],
                    ["index_sensitivity", "index_spread"]),
    "design": (["design.DESIGN_OPTIONS", "design.SCATTER_OPTIONS"],
               ["design_problem", "design_search", "index_spread"]),
}


def _table(ref: str) -> dict[str, str]:
    module, name = ref.split(".")
    return getattr(importlib.import_module(f"maglev_match.cli.{module}"), name)


def _command(name: str) -> click.Command:
    group = get_command(app)
    return group.get_command(click.Context(group), name)


def _parts(text: str) -> set[str]:
    return set(text.split("/"))


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_option_of_a_command_is_an_api_argument_or_presentation(command):
    tables, functions = COMMANDS[command]
    merged = {k: v for ref in tables for k, v in _table(ref).items()}
    arguments = {p for fn in functions for p in inspect.signature(getattr(api, fn)).parameters}
    options = {o for p in _command(command).params for o in p.opts + p.secondary_opts
               if o.startswith("--")}
    mapped = {o for v in merged.values() for o in _parts(v)} | set(
        PARAMETER_SET_OPTIONS.values())
    # the table names real API arguments ...
    unknown_args = sorted(k for k in merged if not _parts(k) & arguments)
    assert not unknown_args, f"{command}: no API argument {unknown_args} in {functions}"
    # ... and options of this command or of its siblings that share the table
    primary = {p.opts[0] for p in _command(command).params if p.opts[0].startswith("--")}
    unmapped = sorted(o for o in primary - PRESENTATION
                      if o not in mapped and not any(s in mapped for p in
                                                     _command(command).params
                                                     if p.opts[0] == o
                                                     for s in p.secondary_opts))
    assert not unmapped, f"{command}: options with no API argument: {unmapped}"
    assert options  # the command was found


def test_the_parameter_set_options_are_the_api_inputs():
    # --preset/--config/--set are the params, config and **overrides of every function
    for fn in ("stability", "hopf_points", "matching_index", "design_map", "speed_sweep"):
        sig = inspect.signature(getattr(api, fn)).parameters
        assert "params" in sig and "config" in sig
        assert any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.values())


def test_map_refuses_a_model_it_does_not_compute(capsys):
    from maglev_match.cli import main

    code = main(["map", "--x", "omega1=120:140:2", "--y", "sigma=3e-4:4e-4:2", "--model",
                 "vehicle", "--workers", "0"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--model" in err and "vehicle" in err
