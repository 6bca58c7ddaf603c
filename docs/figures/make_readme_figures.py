"""Regenerate the README's figures from the current code, by running the README's own
commands.

Each figure of README.md (``![...](docs/img/NAME.png)``) follows a ``bash`` block holding
the ``maglev-match`` command that draws it. This script runs that command exactly as
written (in this process, with ``--out`` moved to a scratch folder), copies the figure to
``docs/img/NAME.png`` and records, in ``docs/img/readme_figures.json``, the command, the
figure file's SHA-256 and a fingerprint of the data drawn (read from the files the command
wrote). ``tests/test_readme.py`` runs the same commands and fails when the fingerprint or
the stored PNG no longer match: the README's figures cannot silently drift from the code.

    python docs/figures/make_readme_figures.py            # every figure
    python docs/figures/make_readme_figures.py hopf_curve # one of them
"""

from __future__ import annotations

import hashlib
import json
import re
import shlex
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
IMG = ROOT / "docs" / "img"
RECORD = IMG / "readme_figures.json"
#: significant digits of the fingerprint values: the data must agree to about 1e-6
DIGITS = 7


def readme_figures(text: str | None = None) -> dict[str, list[str]]:
    """{figure name: the command's arguments} for every README figure drawn from a command:
    the last ``maglev-match`` line of the code block before the image."""
    text = README.read_text() if text is None else text
    out: dict[str, list[str]] = {}
    blocks = list(re.finditer(r"```(?:bash|console)\n(.*?)```", text, re.S))
    for m in re.finditer(r"!\[[^\]]*\]\(docs/img/([\w-]+)\.png\)", text):
        before = [b for b in blocks if b.end() <= m.start()]
        if not before:
            continue
        lines = [ln for ln in before[-1].group(1).splitlines() if "maglev-match " in ln]
        if lines:
            args = shlex.split(lines[-1])
            out[m.group(1)] = args[args.index(next(a for a in args
                                                    if a.endswith("maglev-match"))) + 1:]
    return out


def with_out(args: list[str], folder: Path) -> list[str]:
    """The command with its ``--out`` value moved into ``folder`` (same file name)."""
    args = list(args)
    if "--out" in args:
        k = args.index("--out")
        name = Path(args[k + 1]).name if Path(args[k + 1]).suffix else ""
        args[k + 1] = str(folder / name) if name else str(folder)
    else:
        args += ["--out", str(folder)]
    return args


def _round(v: float) -> float:
    return float(f"{float(v):.{DIGITS}g}")


def fingerprint(folder: Path, command: str) -> dict:
    """The data a README figure draws, from the files ``command`` ('hopf-curve' or 'map')
    wrote into ``folder``: the Hopf curve's CSV (points per branch; omega1, sigma, l1 at
    nine points along each branch) or the map's netCDF (shape, stable count, chi at nine
    grid points)."""
    import numpy as np

    csvs = sorted(f for f in folder.glob("hopf_curve_*.csv") if "_special" not in f.name)
    if command == "hopf-curve" and csvs:
        import csv

        with csvs[0].open() as fh:
            rows = list(csv.reader(fh))
        head, body = rows[0], rows[1:]
        col = {h.split(" (")[0]: k for k, h in enumerate(head)}
        out: dict = {"kind": "hopf-curve", "branches": {}}
        for b in sorted({r[col["branch"]] for r in body}):
            pts = [r for r in body if r[col["branch"]] == b]
            idx = np.unique(np.linspace(0, len(pts) - 1, 9).round().astype(int))
            out["branches"][b] = {
                "points": len(pts),
                "samples": [[_round(pts[i][k]) for k in (1, 2, col["l1"])] for i in idx]}
        return out
    ncs = sorted(folder.glob("map*.nc"))
    if command == "map" and ncs:
        import xarray as xr

        with xr.open_dataset(ncs[0], engine="h5netcdf") as ds:
            chi = np.asarray(ds["chi"].values, float)
            stable = np.asarray(ds["stable"].values)
            ny, nx = chi.shape
            picks = [(j, i) for j in (0, ny // 2, ny - 1) for i in (0, nx // 2, nx - 1)]
            return {"kind": "map", "shape": [ny, nx], "stable": int(np.sum(stable == 1)),
                    "chi": [None if not np.isfinite(chi[j, i]) else _round(chi[j, i])
                            for j, i in picks]}
    raise FileNotFoundError(f"no data of '{command}' in {folder}")


def run_command(args: list[str], folder: Path) -> Path:
    """Run ``maglev-match ARGS`` in this process with ``--out`` in ``folder``; returns
    the PNG it drew."""
    from maglev_match.cli import main

    code = main(with_out(args, folder))
    if code != 0:
        raise RuntimeError(f"maglev-match {' '.join(args)} exited with {code}")
    pngs = sorted(folder.glob("*.png"))
    if not pngs:
        raise FileNotFoundError(f"maglev-match {' '.join(args)} drew no PNG")
    return pngs[0]


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def main(names: list[str]) -> None:
    figures = readme_figures()
    record = json.loads(RECORD.read_text()) if RECORD.exists() else {}
    for name, args in figures.items():
        if names and name not in names:
            continue
        with tempfile.TemporaryDirectory(prefix=f"readme-{name}-") as tmp:
            png = run_command(args, Path(tmp))
            target = IMG / f"{name}.png"
            shutil.copyfile(png, target)
            record[name] = {"command": "maglev-match " + shlex.join(args),
                            "png_sha256": sha256(target),
                            "data": fingerprint(Path(tmp), args[0])}
        print(f"wrote {target.relative_to(ROOT)}")
    record = {k: v for k, v in record.items() if k in figures}
    RECORD.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    print(f"wrote {RECORD.relative_to(ROOT)}")


if __name__ == "__main__":
    main(sys.argv[1:])
