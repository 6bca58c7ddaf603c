"""The guideway irregularity in a --config TOML file (issue 33): an ``[irregularity]`` table
goes through the one validation of ``--irregularity`` (same fields, rules and messages, the
table named in them), gives the same run as the same spec on the command line, is replaced
by ``--irregularity`` and is no parameter for the other commands. (Bad tables exiting 2:
tests/bad_inputs.py, group 'irregularity'.)"""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from maglev_match.cli import main
from maglev_match.cli.speed import irregularity_option
from maglev_match.core.params import ParameterError, load_params
from maglev_match.maglev.irregularity import (
    irregularity_from_table,
    irregularity_in_config,
    parse_irregularity,
)

#: (the table, the same profile on the command line)
SAME = [
    ({"kind": "sine", "wavelength": 25.0, "amplitude": 1e-3},
     "sine:wavelength=25,amplitude=0.001"),
    ({"kind": "joint", "step": 0.002}, "joint:step=2e-3"),
    ({"kind": "settlement", "depth": 0.003, "support": 2}, "settlement:depth=0.003,support=2"),
    ({"kind": "camber", "amplitude": 5e-4}, "camber:amplitude=5e-4"),
    ({"kind": "random", "class": "high", "seeds": 3, "seed0": 4, "lmin": 3, "lmax": 150.0,
      "waves": 64}, "random:class=high,seeds=3,seed0=4,lmin=3,lmax=150,waves=64"),
    ({"kind": "Random", "class": "low"}, "random:class=low"),
]


@pytest.mark.parametrize("table, spec", SAME, ids=[s for _, s in SAME])
def test_a_table_is_the_same_profile_as_the_spec(table, spec):
    a, b = irregularity_from_table(table), parse_irregularity(spec)
    assert a == b
    assert type(a.seeds) is int and type(a.amplitude) is float
    # its text is a spec the option reads back to the same profile
    assert parse_irregularity(a.text) == b


@pytest.mark.parametrize("table, field, rule", [
    ({"kind": "sine", "wavelength": 25.0, "amplitude": -1e-3}, "amplitude", "must be >= 0"),
    ({"kind": "sine", "wavelength": float("nan"), "amplitude": 1e-3}, "wavelength",
     "must be finite"),
    ({"kind": "camber", "amplitude": float("inf")}, "amplitude", "must be finite"),
    ({"kind": "sine", "wavelength": 0.0, "amplitude": 1e-3}, "wavelength", "must be > 0"),
    ({"kind": "random", "class": "low", "seeds": 1.5}, "seeds", "must be a whole number"),
    ({"kind": "random", "class": "low", "seeds": 2.0}, "seeds", "must be a whole number"),
    ({"kind": "random", "class": "low", "seed0": True}, "seed0", "must be a whole number"),
    ({"kind": "random", "class": "low", "seeds": 0}, "seeds", "from 1 to 1000"),
    ({"kind": "random", "class": "medium"}, "class", "must be one of low, high"),
    ({"kind": "random", "class": "low", "lmin": 50, "lmax": 20}, "lmin", "below lmax"),
    ({"kind": "joint", "step": "2mm"}, "step", "must be a number (m)"),
    ({"kind": "joint", "step": True}, "step", "must be a number (m)"),
    ({"kind": "bumps", "height": 1.0}, "kind", "the kind must be one of sine, joint"),
    ({"kind": 3}, "kind", "must be a string"),
    ({"amplitude": 1e-3}, "kind", "missing"),
    ({"kind": "joint", "step": 1e-3, "size": 1e-3}, "size", "unknown field: 'joint' takes"),
    ({"kind": "camber"}, "amplitude", "missing: 'camber' needs amplitude"),
])
def test_bad_tables_name_the_field_the_value_and_the_rule(table, field, rule):
    with pytest.raises(ParameterError) as e:
        irregularity_from_table(table, "cfg.toml [irregularity]")
    assert e.value.field == f"cfg.toml [irregularity] {field}"
    assert rule in e.value.rule


def test_later_checks_name_the_table_too():
    prof = irregularity_from_table({"kind": "settlement", "depth": 1e-3, "support": 9},
                                   "cfg.toml [irregularity]")
    with pytest.raises(ParameterError, match=r"cfg.toml \[irregularity\] support"):
        prof.check(spans=4)


def test_one_entry_array_is_the_table_two_are_refused():
    one = irregularity_from_table([{"kind": "joint", "step": 1e-3}])
    assert one == parse_irregularity("joint:step=0.001")
    with pytest.raises(ParameterError, match="one guideway irregularity"):
        irregularity_from_table([{"kind": "joint", "step": 1e-3},
                                 {"kind": "camber", "amplitude": 1e-3}])


def test_the_option_replaces_the_files_table_and_other_commands_ignore_it(tmp_path):
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('kD = 120\n[irregularity]\nkind = "joint"\nstep = 0.002\n')
    plain = tmp_path / "plain.toml"
    plain.write_text("kD = 120\n")
    assert irregularity_in_config(cfg) == parse_irregularity("joint:step=0.002")
    assert irregularity_in_config(plain) is None and irregularity_in_config(None) is None
    assert irregularity_option(None, cfg) == parse_irregularity("joint:step=0.002")
    assert irregularity_option("camber:amplitude=1e-3", cfg) == "camber:amplitude=1e-3"
    # the table is no parameter: the parameters are the file's others
    assert load_params("turnout-soft", cfg) == load_params("turnout-soft", plain)
    # and a file's parameters are still checked when the table is read
    bad = tmp_path / "bad.toml"
    bad.write_text('kQ = 1\n[irregularity]\nkind = "joint"\nstep = 0.002\n')
    with pytest.raises(ParameterError, match="unknown parameter"):
        irregularity_in_config(bad)


def _speed_json(args, log: list[str] | None = None) -> dict:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["speed", "--from", "90", "--to", "90", "--no-critical", "--workers", "0",
                     "--set", "n_modes=1", "--irregular-spans", "3", "--json", *args])
    assert code == 0
    if log is not None:
        log.append(err.getvalue())
    doc = json.loads(out.getvalue())
    doc.pop("files")
    doc["irregular"].pop("seconds_per_speed")  # wall time, not a result
    return doc


def test_a_config_table_gives_the_same_sweep_as_the_option(tmp_path):
    cfg = tmp_path / "irr.toml"
    cfg.write_text('[irregularity]\nkind = "random"\nclass = "high"\nseeds = 2\n'
                   'waves = 16\nlmin = 4.0\n')
    from_file = _speed_json(["--config", str(cfg), "--out", str(tmp_path / "a")])
    log: list[str] = []
    from_option = _speed_json(["--irregularity", "random:class=high,seeds=2,waves=16,lmin=4",
                               "--out", str(tmp_path / "b")], log)
    assert from_file == from_option
    # a progress line per finished run (issue 33: the runs are a job of their own), and
    # the checkpoint of the sweep, its runs with it, is spent once the files are written
    assert "1/2 irregular runs done" in log[0] and "2/2 irregular runs done" in log[0]
    assert not (tmp_path / "b" / "speed_unit.nc.tiles").exists()
    assert from_file["irregular"]["seeds"] == [0, 1]
    # (that --irregularity replaces the file's table: the test above, on
    # irregularity_option, the one function the command reads the profile with)


def test_the_documented_table_is_the_documented_spec(tmp_path):
    """The TOML example of docs/speed.md, 'An irregular guideway', as written: its
    parameters load and its table is the spec the text names."""
    import re
    import tomllib
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "speed.md").read_text()
    section = text.split("## An irregular guideway", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```toml\n(.*?)```", section, re.S).group(1)
    spec = re.search(r"first command above's profile \(`([^`]+)`\)", section).group(1)
    assert f"--irregularity {spec}" in section  # the command it stands for
    cfg = tmp_path / "run.toml"
    cfg.write_text(block)
    assert irregularity_in_config(cfg) == parse_irregularity(spec)
    assert load_params("turnout-soft", cfg).kD == tomllib.loads(block)["kD"]
