"""Execute the tutorial notebooks of examples/ and save them with their outputs (text and
figures), which the documentation shows on the tutorial pages (docs/hooks/notebooks.py).

    python docs/figures/run_notebooks.py [NAME ...]

Run it after changing a notebook or anything it shows; tests/test_notebooks.py executes
every notebook again and fails when a stored notebook lacks its outputs.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def run(path: Path) -> None:
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    env_path = os.pathsep.join([str(ROOT / "src"), *filter(None, [os.environ.get("PYTHONPATH")])])
    os.environ["PYTHONPATH"] = env_path
    os.environ.pop("MPLBACKEND", None)  # the kernel's inline backend stores the figures
    os.environ["MAGLEV_MATCH_PROGRESS"] = "0"  # no timings in the stored outputs
    with tempfile.TemporaryDirectory(prefix="maglev-nb-") as cwd:
        nbclient.NotebookClient(nb, timeout=900, kernel_name="python3",
                                resources={"metadata": {"path": cwd}}).execute()
    for cell in nb.cells:  # reproducible files: no per-run ids or timings
        cell.get("metadata", {}).pop("execution", None)
    nbformat.write(nb, path)
    print(f"executed and saved {path.relative_to(ROOT)}")


if __name__ == "__main__":
    names = sys.argv[1:]
    for nb_path in sorted((ROOT / "examples").glob("*.ipynb")):
        if not names or any(n in nb_path.name for n in names):
            run(nb_path)
