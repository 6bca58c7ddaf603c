"""The README keeps its word: every ``maglev-match`` command of its code blocks runs as
written and writes what it says; every command of its table accepts ``--out``; the sample
output of ``index`` carries the numbers the command prints; and the README's figures are
the ones its commands draw now (``docs/figures/make_readme_figures.py`` regenerates them;
this test fails when the stored figure or its data drift from the code).

The commands run once, in one scratch folder (module fixture), and every check reads the
same runs."""

from __future__ import annotations

import hashlib
import json
import re
import shlex
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
sys.path.insert(0, str(ROOT / "docs" / "figures"))
import make_readme_figures as figures  # noqa: E402

WROTE = re.compile(r"wrote (.+)")


def readme_commands() -> list[list[str]]:
    """The arguments of every ``maglev-match`` command line in a code block (the install
    and test commands of the first section are run by CI itself, see .ci/run)."""
    out = []
    for block in re.finditer(r"```(bash|console)\n(.*?)```", README, re.S):
        for line in block.group(2).splitlines():
            if block.group(1) == "console":  # a console block: its commands follow "$ "
                if not line.startswith("$ "):
                    continue
                line = line[2:]
            line = line.strip()
            if "maglev-match " not in line or "pip install" in line:
                continue
            args = shlex.split(line)
            k = next(i for i, a in enumerate(args) if a.endswith("maglev-match"))
            out.append(args[k + 1:])
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Each README command run as written, in a fresh folder: {command line: (exit code,
    stdout, stderr)}."""
    import contextlib
    import io
    import os

    from maglev_match.cli import main

    cwd = tmp_path_factory.mktemp("readme")
    old = os.getcwd()
    os.chdir(cwd)
    results = {}
    try:
        for args in readme_commands():
            out, err = io.StringIO(), io.StringIO()
            t0 = time.process_time()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = main(list(args))
            results[shlex.join(args)] = (code, out.getvalue(), err.getvalue())
            print(f"maglev-match {shlex.join(args)}: {time.process_time() - t0:.1f} s CPU")
    finally:
        os.chdir(old)
    return cwd, results


def test_the_readme_has_the_commands_it_shows():
    cmds = [a[0] for a in readme_commands()]
    assert {"index", "hopf-curve", "map"} <= set(cmds), cmds


def test_every_readme_command_runs_and_writes_the_files_it_names(runs):
    cwd, results = runs
    for line, (code, out, err) in results.items():
        assert code == 0, f"maglev-match {line}: exit {code}\n{err[-2000:]}"
        written = [f.strip() for m in WROTE.finditer(out) for f in
                   re.split(r",\s*|\s+and\s+", m.group(1))]
        args = shlex.split(line)
        if "--out" in args:
            target = Path(args[args.index("--out") + 1])
            folder = target if not target.suffix else target.parent
        else:
            folder = Path("maglev-match-out") / args[0]
        assert (cwd / folder).is_dir(), f"{line}: no folder {folder}"
        assert written, f"{line}: names no file it wrote"
        for f in written:
            path = cwd / f
            assert path.is_file() and path.stat().st_size > 0, f"{line}: {f}"
            assert path.parent == cwd / folder, f"{line}: {f} is not in {folder}"


def test_index_sample_output_has_the_numbers_the_command_prints(runs):
    """The README's sample of `maglev-match index` shows the numbers of the command."""
    _, results = runs
    code, out, _ = results["index"]
    sample = re.search(r"\$ \.venv/bin/maglev-match index\n(.*?)```", README, re.S).group(1)
    keys = (r"chi = ([\d.]+)", r"w0 = ([\d.]+) mm", r"h  = ([\d.]+) mm",
            r"max Re\(lambda\) = ([-\d.]+)")
    for key in keys:
        shown, printed = re.search(key, sample), re.search(key, out)
        assert shown and printed, key
        assert shown.group(1) == printed.group(1), (key, shown.group(1), printed.group(1))


def test_every_command_of_the_readme_table_accepts_out():
    from maglev_match.cli import all_commands

    table = re.search(r"\| command \| what it computes \|\n(.*?)\n\n", README, re.S).group(1)
    names = re.findall(r"^\| `([\w-]+)", table, re.M)
    commands = all_commands()
    assert set(names) == set(commands), set(commands) ^ set(names)
    for name in names:
        if name == "explore":  # serves a page; its exports are downloaded from the page
            continue
        opts = {o for p in commands[name].params for o in p.opts}
        assert "--out" in opts, f"{name} has no --out"


def test_readme_figures_are_drawn_from_the_current_code(runs):
    """Each README figure is the one its command draws now: the stored PNG is the one the
    script wrote, and the data drawn (recomputed by the runs above) match the fingerprint
    stored beside it. On failure: python docs/figures/make_readme_figures.py"""
    cwd, results = runs
    record = json.loads(figures.RECORD.read_text())
    listed = figures.readme_figures()
    assert set(record) == set(listed), "README figures without a record (run the script)"
    for name, args in listed.items():
        rec = record[name]
        assert rec["command"] == "maglev-match " + shlex.join(args), name
        png = figures.IMG / f"{name}.png"
        assert hashlib.sha256(png.read_bytes()).hexdigest() == rec["png_sha256"], (
            f"{png} is not the figure the script drew")
        code, _, _ = results[shlex.join(args)]
        assert code == 0
        target = Path(args[args.index("--out") + 1])
        folder = cwd / (target if not target.suffix else target.parent)
        assert _same(figures.fingerprint(folder, args[0]), rec["data"]), (
            f"the data of {name}.png changed: run python docs/figures/make_readme_figures.py")


def _same(a, b, rtol: float = 1e-5) -> bool:
    """Equal structures, numbers equal to ``rtol`` (the fingerprint keeps 7 digits; a
    value on a rounding boundary may round either way on another machine)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k], rtol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y, rtol) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) or isinstance(b, float):
        return a is not None and b is not None and abs(a - b) <= rtol * max(abs(a), abs(b))
    return a == b


def test_readme_design_answer_meets_the_headline_and_one_percent_less_does_not(runs):
    """The README's design example as the README ran it: the beam it answers (the EI the
    README quotes) meets chi >= 5 on the headline index with both parts, re-checked by the
    full index, and 1 % less EI does not; the requirement binds chi_simulation."""
    from maglev_match.analyses.matching import matching_index
    from maglev_match.core.params import load_preset

    _, results = runs
    line = next(k for k in results if k.startswith("design "))
    code, out, _ = results[line]
    assert code == 0
    ei = float(re.search(r"EI = ([0-9.e+-]+) \(range", out).group(1))
    quoted = float(re.search(r"It answers EI = ([0-9.e+-]+) N m\^2", README).group(1))
    assert ei == pytest.approx(quoted, rel=5e-4)  # the README says what the command answers
    base = load_preset("turnout-soft")
    again = matching_index(base.replace(EI=ei))
    tol = 1e-5  # (the printed EI has 6 digits; chi is at the bound there)
    assert again.chi == min(again.chi_paper, again.chi_simulation)
    assert again.chi_paper >= 5.0 and again.chi_simulation >= 5.0 * (1 - tol)
    assert again.reading_basis == "simulation"
    shown = float(re.search(r"full index there: chi = ([0-9.]+)", out).group(1))
    assert shown == pytest.approx(again.chi, rel=1e-4)
    less = matching_index(base.replace(EI=0.99 * ei))
    assert less.chi < 5.0

