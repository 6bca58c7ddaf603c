"""Command line output: progress off a terminal, --out folder-or-file, engineering quantities
as --param, presets with their changes, stability tables without spurious pairs, help texts.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from maglev_match.cli import app, main
from maglev_match.cli.common import OUTPUT_ROOT, output_target, progress_report
from maglev_match.cli.stability import IMAG_RTOL, table_eigenvalues
from maglev_match.core.params import load_preset

PROGRESS_LINE = re.compile(r"^maglev-match (\S+) \[ *\d+\.\d s\] (.+)$")


def run(capsys, *args):
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


# ----- progress ----------------------------------------------------------------------------
def test_progress_lines_on_stderr_off_a_terminal_and_json_stays_pure(capsys):
    # captured stderr is not a terminal: each stage is one plain line there
    code, out, err = run(capsys, "simulate", "--t", "0.05", "--n-save", "11", "--json")
    assert code == 0
    doc = json.loads(out)  # stdout is exactly one JSON object
    assert doc["outcome"] in ("converged", "running", "collision")
    lines = [m for m in map(PROGRESS_LINE.match, err.splitlines()) if m]
    # one line per stage (a slow machine adds 'still ...' lines every few seconds)
    lines = [m for m in lines if not m.group(2).startswith("still ")]
    assert [m.group(1) for m in lines] == ["simulate", "simulate"]
    assert "simulating model A for 0.05 s" in lines[0].group(2)
    assert doc["outcome"] in lines[1].group(2)


def test_progress_report_plain_lines_one_per_stage_and_tile(capsys):
    with progress_report("map", tty=False) as prog:
        prog.stage("map omega1 x sigma: 4 tiles ...")
        prog.update("fine-grained news is for terminals only")
        for done in (0, 1, 1, 2, 3, 4):
            prog.tiles(done, 4)
    err = capsys.readouterr().err.splitlines()
    msgs = [PROGRESS_LINE.match(line).group(2) for line in err]
    msgs = [m for m in msgs if not m.startswith("still ")]  # a heartbeat on a busy machine
    assert [m.split(",")[0] for m in msgs] == [
        "map omega1 x sigma: 4 tiles ...", "0/4 tiles done", "1/4 tiles done",
        "2/4 tiles done", "3/4 tiles done", "4/4 tiles done"]
    # an estimate of the time left once two tiles finished after the first (the first of
    # each worker pays for loading and compiling), none when all are done
    assert msgs[2] == "1/4 tiles done" and msgs[3] == "2/4 tiles done", msgs
    assert re.search(r", about \d+ s left$", msgs[4]), msgs
    assert msgs[1] == "0/4 tiles done" and msgs[5] == "4/4 tiles done"


def test_time_left_is_not_fooled_by_the_compiling_first_units():
    """The finishing times of a 31-speed `speed` sweep on two workers as measured (the last
    five extrapolated at the same pace): both workers compile first, then take 0.5-1.2 s
    per speed. The estimate is within a factor 3 of what was really left from
    the first line that shows one, never the minutes the first interval suggests."""
    from maglev_match.cli.common import time_left

    times = [11.3, 19.9, 21.1, 22.3, 23.2, 24.0, 24.9, 25.3, 25.5, 26.4, 26.4, 27.3, 27.9,
             28.3, 29.1, 29.3, 29.9, 31.0, 31.0, 31.5, 32.3, 32.5, 33.1, 33.5, 34.3, 34.7,
             35.2, 35.6, 36.0, 36.3, 36.5]
    finished, shown = [], 0
    for done, t in enumerate(times, start=1):
        finished.append((done, t))
        left = time_left(finished, done, len(times), t)
        if done < 3:
            assert left is None  # nothing to go on but compiling units
            continue
        truth = times[-1] - t
        assert truth / 3 - 1.0 <= left <= 3 * truth + 1.0, (done, left, truth)
        shown += 1
    assert shown == len(times) - 2
    # steady units: the plain rate
    assert time_left([(1, 10.0), (2, 11.0), (3, 12.0), (4, 13.0)], 4, 10, 13.0) == \
        pytest.approx(6.0)


def test_progress_report_repeats_a_long_stage_with_its_latest_detail(capsys):
    """Off a terminal a stage that lasts longer than the heartbeat is repeated ('still
    ...'), with the latest fine-grained news, so a log never falls silent for long."""
    import time

    from maglev_match.cli.common import ProgressReport

    text = ""
    with ProgressReport("index", tty=False, heartbeat=0.2) as prog:
        prog.stage("computing the matching index ...")
        prog.update("step 7")
        # wait for two heartbeats however slow the machine is (no fixed sleep)
        deadline = time.monotonic() + 120.0
        while text.count("still ") < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
            text += capsys.readouterr().err
    text += capsys.readouterr().err
    msgs = [PROGRESS_LINE.match(line).group(2) for line in text.splitlines()]
    assert msgs[0] == "computing the matching index ..."
    assert len(msgs) >= 3 and all(m == "still computing the matching index (step 7)"
                                  for m in msgs[1:]), msgs


# ----- --out -------------------------------------------------------------------------------
def test_output_target_folder_file_and_default(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    folder, stem = output_target(None, "root-locus", "root_locus_unit_L")
    assert (folder, stem) == (Path(OUTPUT_ROOT) / "root-locus", "root_locus_unit_L")
    assert folder.is_dir()
    folder, stem = output_target(Path("res"), "cycles", "cycles_unit_omega1")
    assert (folder, stem) == (Path("res"), "cycles_unit_omega1") and folder.is_dir()
    folder, stem = output_target(Path("a/b/run.csv"), "simulate", "simulation_unit")
    assert (folder, stem) == (Path("a/b"), "run") and folder.is_dir()
    # a number after the last dot is part of a folder's name, not a file type
    folder, stem = output_target(Path("runs/tau_0.001"), "index", "index_unit")
    assert (folder, stem) == (Path("runs/tau_0.001"), "index_unit") and folder.is_dir()


def test_gitignore_covers_the_default_output_folder():
    root = Path(__file__).resolve().parents[1]
    lines = (root / ".gitignore").read_text().split()
    assert f"/{OUTPUT_ROOT}/" in lines or f"{OUTPUT_ROOT}/" in lines


def test_root_locus_out_default_folder_and_file(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["root-locus", "--from", "80", "--to", "120", "--steps", "3", "--json"]
    assert run(capsys, *args)[0] == 0
    default = tmp_path / OUTPUT_ROOT / "root-locus"
    assert sorted(p.name for p in default.iterdir()) == [
        "root_locus_unit_omega1.csv", "root_locus_unit_omega1.png", "root_locus_unit_omega1.svg"]
    assert run(capsys, *args, "--out", "folder")[0] == 0
    assert (tmp_path / "folder" / "root_locus_unit_omega1.csv").is_file()
    code, out, _ = run(capsys, *args, "--out", "files/rl.csv")
    assert code == 0
    assert json.loads(out)["csv"] == str(Path("files/rl.csv"))
    assert sorted(p.name for p in (tmp_path / "files").iterdir()) == ["rl.csv", "rl.png",
                                                                      "rl.svg"]


def test_simulate_out_accepts_a_folder_and_a_file(capsys, tmp_path):
    base = ["simulate", "--t", "0.02", "--n-save", "5", "--json"]
    assert run(capsys, *base, "--out", str(tmp_path / "dir"), "--plot",
               str(tmp_path / "figs"))[0] == 0
    assert (tmp_path / "dir" / "simulation_unit.nc").is_file()
    assert (tmp_path / "figs" / "simulation_unit.png").is_file()
    assert run(capsys, *base, "--out", str(tmp_path / "h.csv"))[0] == 0
    rows = (tmp_path / "h.csv").read_text().splitlines()
    assert len([r for r in rows if r and not r.startswith("#")]) == 1 + 5  # header + samples
    assert run(capsys, *base, "--out", str(tmp_path / "h.txt"))[0] == 2


def test_map_and_report_defaults_live_in_the_output_folder():
    """The defaults of map/report/reproduce are no longer files in the working folder."""
    import inspect

    from maglev_match.cli import index, report

    for fn in (index.map_command, report.report_command, report.reproduce_command):
        assert inspect.signature(fn).parameters["out"].default is None


# ----- engineering quantities ---------------------------------------------------------------
def test_hopf_param_L_agrees_with_the_direct_omega1_search(capsys):
    code, out, _ = run(capsys, "hopf", "--param", "L", "--from", "13", "--to", "30",
                       "--steps", "30", "--json")
    assert code == 0
    pts = json.loads(out)["points"]
    assert len(pts) >= 1 and pts[0]["converged"]
    L = pts[0]["L"]
    p = load_preset("turnout-soft").replace(L=L)  # L -> omega1, sigma by the beam formulas
    assert pts[0]["omega1"] == pytest.approx(p.omega1, rel=1e-9)
    assert pts[0]["sigma"] == pytest.approx(p.sigma, rel=1e-9)
    # the independent route: omega1 varied directly at the sigma that L gives
    code, out, _ = run(capsys, "hopf", "--param", "omega1", "--from", f"{0.9 * p.omega1!r}",
                       "--to", f"{1.1 * p.omega1!r}", "--steps", "20", "--set",
                       f"sigma={p.sigma!r}", "--json")
    assert code == 0
    direct = json.loads(out)["points"]
    assert len(direct) == 1
    assert direct[0]["omega1"] == pytest.approx(p.omega1, rel=1e-6)
    assert direct[0]["frequency"] == pytest.approx(pts[0]["frequency"], rel=1e-6)
    # the crossing speed is per metre of span: a central difference of max Re(lambda) in L
    from maglev_match.dynamics.equilibria import stability
    from maglev_match.maglev.models import build_system

    assert pts[0]["others_stable"]
    h = 1e-4
    mr = [stability(build_system(p.replace(L=L + d), "unit")).max_real_part for d in (h, -h)]
    assert pts[0]["crossing_speed"] == pytest.approx((mr[0] - mr[1]) / (2 * h), rel=1e-4)


def test_engineering_param_that_changes_nothing_is_refused(capsys):
    # alpha1 sets omega1 and sigma explicitly: the span L moves neither (model A)
    code, _, err = run(capsys, "hopf", "--param", "L", "--from", "13", "--to", "30",
                       "--preset", "alpha1")
    assert code == 2
    assert "--param" in err and "L" in err and "omega1" in err


def test_set_warning_names_both_values(capsys):
    code, out, err = run(capsys, "stability", "--set", "omega1=100", "--set", "EI=3e10")
    assert code == 0, err
    line = next(ln for ln in err.splitlines() if ln.startswith("warning:"))
    assert "omega1 = 100" in line and "EI = 3e+10" in line


# ----- presets -----------------------------------------------------------------------------
def test_presets_show_what_changes_against_the_base(capsys):
    code, out, _ = run(capsys, "presets")
    assert code == 0
    assert "paper-variant-kD (changes vs turnout-soft: kD 150 -> 96.6488)" in out
    assert "paper-variant-ke (changes vs turnout-soft: ke 25 -> 16.7204)" in out
    assert "paper-variant-omega0 (changes vs turnout-soft: omega0 130 -> 37.1318)" in out
    assert "turnout-soft (a base preset)" in out
    code, out, _ = run(capsys, "presets", "--json")
    rows = {r["name"]: r for r in json.loads(out)["presets"]}
    assert rows["paper-variant-kD"]["changes"] == {"kD": {"base": 150.0, "value": 96.6488}}
    stiff = rows["turnout-stiff"]["changes"]
    assert stiff["EI"] == {"base": 1.96e10, "value": 2.26e10}
    # omega1 derives from EI: (2.26 / 1.96)^(1/2) times the base value
    assert stiff["omega1"]["value"] == pytest.approx(
        stiff["omega1"]["base"] * (2.26 / 1.96) ** 0.5, rel=1e-12)
    assert all(r["description"] for r in rows.values())


# ----- stability tables ----------------------------------------------------------------------
def test_model_b_stability_table_lists_each_pair_once_without_spurious_pairs(capsys):
    code, out, _ = run(capsys, "stability", "--model", "vehicle")
    assert code == 0
    rows = [[c.strip() for c in ln.split("│")[1:-1]] for ln in out.splitlines()
            if ln.startswith("│")]
    assert rows
    imag = np.array([float(r[2]) for r in rows])
    assert not np.any((np.abs(imag) > 0) & (np.abs(imag) < 1e-9))
    assert np.all(imag >= 0)
    # each real eigenvalue once, each conjugate pair once: together the whole spectrum
    assert int(np.sum(imag == 0) + 2 * np.sum(imag > 0)) == 40


def test_table_eigenvalues_rounds_only_noise():
    eig = np.array([-1 + 2j, -1 - 2j, -3 + 3.2e-13j, -3 - 3.2e-13j, -5.0, -7 + 1e-6j,
                    -7 - 1e-6j])
    rows = table_eigenvalues(eig)
    assert [k for k, _ in rows] == [0, 2, 3, 4, 5]
    assert [z for _, z in rows] == [-1 + 2j, -3 + 0j, -3 + 0j, -5 + 0j, -7 + 1e-6j]
    assert IMAG_RTOL * 7 < 1e-6  # a true pair of small frequency is kept


# ----- help texts ----------------------------------------------------------------------------
COMMANDS = ["stability", "root-locus", "presets", "hopf", "hopf-curve", "cycles", "simulate",
            "index", "map", "report", "reproduce", "sensitivity", "design"]


@pytest.mark.parametrize("command", COMMANDS)
def test_help_has_no_bool_type_and_fits_100_columns(capsys, monkeypatch, command):
    monkeypatch.setenv("COLUMNS", "100")
    code, out, _ = run(capsys, command, "--help")
    assert code == 0
    assert "<bool>" not in out
    assert "--json" in out or command in ("presets",)
    assert max(len(ln) for ln in out.splitlines()) <= 100


def test_command_help_is_unwrapped_inside_paragraphs():
    from maglev_match.cli import load_all_commands

    load_all_commands()  # (the program itself loads only the command it runs)
    for info in app.registered_commands:
        for paragraph in (info.help or "").split("\n\n"):
            assert "\n" not in paragraph, info.name


def test_progress_report_on_a_terminal_prints_no_plain_lines(capsys):
    with progress_report("map", tty=True) as prog:
        prog.stage("map omega1 x sigma: 4 tiles ...")
        prog.tiles(1, 3)
    err = capsys.readouterr().err
    assert not any(PROGRESS_LINE.match(line) for line in err.splitlines())


def test_engineering_param_outside_the_model_is_refused(capsys):
    # the unit spacing s belongs to model B only
    code, _, err = run(capsys, "root-locus", "--param", "s", "--from", "0.5", "--to", "1.5",
                       "--steps", "3")
    assert code == 2
    assert "does not enter this model" in err


def test_at_warns_when_an_explicit_omega1_overrides_the_span():
    from maglev_match.api.inputs import resolve_model
    from maglev_match.core.params import ParameterWarning

    studied = resolve_model(load_preset("alpha1"), "unit")
    with pytest.warns(ParameterWarning) as caught:
        p = studied.with_values(L=20.0).params
    texts = [str(w.message) for w in caught]
    assert any(re.search(r"omega1 = 100 .*L = 20", t) for t in texts)
    assert any(re.search(r"sigma = 0.0004 .*L = 20", t) for t in texts)
    assert p.omega1 == 100.0 and p.L == 20.0


def test_map_out_folder_gets_the_default_name(capsys, tmp_path):
    code, out, err = run(capsys, "map", "--x", "omega1=120:140:2", "--y", "sigma=3e-4:4e-4:2",
                         "--workers", "0", "--no-simulation", "--out", str(tmp_path / "maps"),
                         "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["netcdf"] == str(tmp_path / "maps" / "map_omega1_sigma.nc")
    assert (tmp_path / "maps" / "map_omega1_sigma.nc").is_file()
    assert (tmp_path / "maps" / "map_omega1_sigma.png").is_file()
    # the tiles, then the map's self-check as its own stage (a "still ..." heartbeat may
    # come between any two lines on a busy machine: it is not a stage)
    stages = [m.group(2) for m in map(PROGRESS_LINE.match, err.splitlines())
              if m and not m.group(2).startswith("still ")]
    assert stages[-2:] == ["1/1 tiles done",
                           "spot check: recomputing sample points one by one ..."]


def test_default_file_names_carry_the_parameter_set(capsys, tmp_path, monkeypatch):
    # a run with other values does not overwrite the standstill answer
    monkeypatch.chdir(tmp_path)
    assert run(capsys, "stability")[0] == 0
    assert run(capsys, "stability", "--set", "kD=120", "--set", "tau=0.001")[0] == 0
    assert run(capsys, "stability", "--preset", "turnout-stiff")[0] == 0
    names = sorted(p.name for p in (tmp_path / OUTPUT_ROOT / "stability").iterdir())
    assert names == ["stability_unit.csv", "stability_unit_kD-120_tau-0.001.csv",
                     "stability_unit_turnout-stiff.csv"]
    # an explicit --out keeps its own names
    assert run(capsys, "stability", "--set", "kD=120", "--out", "res")[0] == 0
    assert (tmp_path / "res" / "stability_unit.csv").is_file()
