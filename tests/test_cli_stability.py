"""Command line: stability, root-locus, presets; JSON shape and user-error handling."""

import json
import subprocess
import sys

import numpy as np
import pytest

from maglev_match.cli import main


def run(capsys, *args):
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_stability_json_unit(capsys):
    code, out, _ = run(capsys, "stability", "--set", "omega1=100", "--set", "sigma=4e-4", "--json")
    assert code == 0
    doc = json.loads(out)
    assert isinstance(doc["stable"], bool)
    eig = np.array(doc["eigenvalues"])
    assert eig.shape == (9, 2)
    assert doc["max_real_part"] == pytest.approx(eig[:, 0].max())
    assert doc["stable"] == (doc["max_real_part"] < 0)


def test_stability_json_vehicle_has_equilibrium(capsys):
    code, out, _ = run(capsys, "stability", "--model", "vehicle", "--preset", "turnout-stiff",
                       "--json")
    assert code == 0
    doc = json.loads(out)
    assert len(doc["equilibrium"]) == 40
    assert len(doc["eigenvalues"]) == 40


def test_stability_table(capsys):
    code, out, _ = run(capsys, "stability")
    assert code == 0
    assert "max Re(lambda)" in out


def test_root_locus_writes_csv_and_png(capsys, tmp_path):
    code, out, _ = run(capsys, "root-locus", "--param", "omega1", "--from", "40", "--to", "190",
                       "--steps", "31", "--out", str(tmp_path), "--json")
    assert code == 0
    doc = json.loads(out)
    csv = tmp_path / "root_locus_unit_omega1.csv"
    assert csv.exists() and (tmp_path / "root_locus_unit_omega1.png").stat().st_size > 1000
    rows = csv.read_text().splitlines()
    assert len(rows) == 1 + 31 * 9
    assert rows[0] == ("omega1 (rad/s),index,re (1/s),im (rad/s),max_real_part (1/s),"
                       "equilibrium_converged")  # SI values, units in the headers
    # a stability change is reported where the max real part changes sign
    mr = np.array(doc["max_real_part"])
    assert (len(doc["stability_changes"]) > 0) == bool(np.any(np.diff(np.sign(mr)) != 0))


@pytest.mark.parametrize(
    "args,fragment",
    [
        (["stability", "--set", "m=-5"], "'m' = -5.0: must be > 0"),
        (["stability", "--set", "colour=3"], "'colour'"),
        (["stability", "--model", "train"], "'--model' = 'train'"),
        (["stability", "--preset", "nope"], "no such preset"),
        (["root-locus", "--param", "omega9"], "'--param' = 'omega9'"),
        (["root-locus", "--from", "100", "--to", "50"], "increasing"),
        (["root-locus", "--param", "omega1", "--from", "-10", "--to", "50"], "'omega1'"),
    ],
)
def test_user_errors_exit_2_with_message(capsys, args, fragment):
    code, out, err = run(capsys, *args)
    assert code == 2
    assert fragment in " ".join(err.split())
    assert "Traceback" not in err


def test_console_script_exit_code_and_no_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "maglev_match.cli", "stability", "--set", "kD=-1"],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "kD" in proc.stderr
