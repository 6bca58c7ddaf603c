"""The answers do not move when the code does: outputs recorded before a restructure,
compared after.

``tests/golden/`` holds the JSON answers (and, for the map, every variable of its netCDF
file) of a fixed set of commands, recorded with the code of the commit that added each file.
Each test runs the same command line now and compares every number to a relative 1e-12
(the recorded values were bit-identical after the package's restructure; the margin only
absorbs the last bit of a reordered sum), and every string, flag and count exactly. Values
that are not answers are left out: elapsed times, the paths of written files and the
package version.

Record again (only when a change of an answer is intended and explained in its commit)::

    python tests/test_recorded_outputs.py [NAME ...]
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).resolve().parent / "golden"
RTOL = 1e-12

#: name -> command line (``OUT`` is replaced by a scratch folder)
CASES: dict[str, list[str]] = {
    "stability": ["stability", "--json"],
    "hopf": ["hopf", "--json"],
    "index_turnout_soft": ["index", "--json"],
    "index_turnout_stiff": ["index", "--preset", "turnout-stiff", "--json"],
    "index_tau_1ms": ["index", "--set", "tau=0.001", "--json"],
    "cycles": ["cycles", "--json"],
    "speed_3": ["speed", "--from", "0", "--to", "100", "--step", "50", "--workers", "0",
                "--out", "OUT", "--json"],
    "map_6x4": ["map", "--x", "omega1=80:130:6", "--y", "sigma=3e-4:5e-4:4", "--workers", "0",
                "--out", "OUT", "--json"],
}

#: keys whose values are not answers (times, file paths, versions)
VOLATILE = {"elapsed_s", "elapsed", "files", "netcdf", "figures", "log", "tiles", "csv",
            "version", "wall_s", "cpu_s"}


def _clean(value):
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [_clean(v) for v in value]
    return value


def _plain(values: np.ndarray):
    """An array as nested lists of numbers and strings (bytes decoded)."""
    if values.dtype.kind in "SO":
        return [_plain(np.asarray(v)) if np.ndim(v) else
                (v.decode() if isinstance(v, bytes) else v) for v in values] \
            if values.ndim else (values.item().decode() if isinstance(values.item(), bytes)
                                 else values.item())
    if values.dtype.kind == "M":
        return values.astype(str).tolist()
    return values.tolist()


def run_case(name: str, folder: Path) -> dict:
    """The cleaned JSON answer of case ``name`` (and the map's netCDF variables)."""
    args = [a.replace("OUT", str(folder)) for a in CASES[name]]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.run([sys.executable, "-m", "maglev_match.cli", *args],
                          capture_output=True, text=True, env=env, cwd=folder, timeout=3600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    doc = json.loads(proc.stdout)
    netcdf = doc.get("netcdf") if isinstance(doc, dict) else None
    doc = _clean(doc)
    if netcdf:
        import xarray as xr

        with xr.open_dataset(netcdf) as ds:
            doc["dataset"] = {
                name: {"dims": list(var.dims), "values": _plain(np.asarray(var.values))}
                for name, var in {**ds.coords, **ds.data_vars}.items()}
    return doc


def compare(now, then, where: str = "") -> list[str]:
    """Every difference between two answers: numbers beyond RTOL, anything else exactly."""
    if isinstance(then, dict):
        if not isinstance(now, dict):
            return [f"{where}: {type(now).__name__} instead of a mapping"]
        out = [f"{where}.{k}: missing" for k in then if k not in now]
        out += [f"{where}.{k}: new" for k in now if k not in then]
        for k in then:
            if k in now:
                out += compare(now[k], then[k], f"{where}.{k}")
        return out
    if isinstance(then, list):
        if not isinstance(now, list) or len(now) != len(then):
            return [f"{where}: length {len(now) if isinstance(now, list) else '-'} "
                    f"instead of {len(then)}"]
        out: list[str] = []
        for i, (a, b) in enumerate(zip(now, then, strict=True)):
            out += compare(a, b, f"{where}[{i}]")
        return out
    if isinstance(then, bool) or not isinstance(then, int | float) or \
            not isinstance(now, int | float) or isinstance(now, bool):
        return [] if now == then else [f"{where}: {now!r} instead of {then!r}"]
    a, b = float(now), float(then)
    if math.isnan(b):
        return [] if math.isnan(a) else [f"{where}: {a!r} instead of nan"]
    if a == b or abs(a - b) <= RTOL * max(abs(a), abs(b)):
        return []
    return [f"{where}: {a!r} instead of {b!r}"]


@pytest.mark.parametrize("name", list(CASES))
def test_answer_is_the_recorded_one(name, tmp_path):
    then = json.loads((GOLDEN / f"{name}.json").read_text())
    now = run_case(name, tmp_path)
    diffs = compare(now, then, name)
    assert not diffs, "\n".join(diffs[:40])


def record(names: list[str]) -> None:
    GOLDEN.mkdir(exist_ok=True)
    for name in names or list(CASES):
        with tempfile.TemporaryDirectory() as tmp:
            doc = run_case(name, Path(tmp))
        (GOLDEN / f"{name}.json").write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        print(f"recorded {name}")


if __name__ == "__main__":
    record(sys.argv[1:])
