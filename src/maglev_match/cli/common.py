"""Options and helpers shared by every command of the command line."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich.console import Console

from maglev_match.params import (
    DEFAULT_PRESET,
    PARAMETER_DOCS,
    ParameterError,
    Params,
    load_params,
)

console = Console()
console_err = Console(stderr=True)


class UserError(Exception):
    """A mistake in the command line that is not about a parameter value."""


PresetOpt = Annotated[
    str, typer.Option("--preset", help="Shipped parameter preset (see `maglev-match presets`).")
]
ConfigOpt = Annotated[
    Path | None, typer.Option("--config", help="User TOML file applied on top of the preset.")
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option("--set", help="Override one value, NAME=VALUE (repeatable), e.g. --set kD=120."),
]
ModelOpt = Annotated[
    str, typer.Option("--model", help="'unit' (model A, 9 states), 'vehicle' (model B) or a "
                      "user model file FILE.py (see docs/user-models.md).")
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object (SI units).")]
OutOpt = Annotated[Path | None, typer.Option("--out", help="Output file or folder.")]

DEFAULT_PRESET_NAME = DEFAULT_PRESET


def params_from_options(preset: str, config: Path | None, sets: list[str] | None) -> Params:
    """Preset, then --config, then --set overrides."""
    return load_params(preset, config, sets or [])


def check_model(model: str) -> str:
    if model not in ("unit", "vehicle"):
        raise ParameterError("--model", model,
                             "must be 'unit', 'vehicle' or a model file ending in .py")
    return model


def print_warnings(warnings) -> None:
    """Warnings of a computation on stderr, one line each (stdout stays clean for --json)."""
    for w in warnings:
        console_err.print(f"[yellow]warning:[/] {w}", highlight=False)


def check_param(system, model: str, name: str, option: str) -> None:
    """``name`` must be a parameter of the chosen model."""
    if name not in system.param_names:
        raise ParameterError(
            option, name,
            f"model '{model}' has no such parameter; choose one of {', '.join(system.param_names)}",
        )


def validate_value(params: Params, name: str, value: float) -> None:
    """A parameter value outside its rule (e.g. omega1 <= 0) is a user error."""
    if name in PARAMETER_DOCS:
        params.replace(**{name: value})


def unit_of(name: str) -> str:
    """The SI unit of a parameter, '' if unknown."""
    return PARAMETER_DOCS.get(name, ("", ""))[0]


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays, complex numbers and dataclasses for json.dumps.
    Complex numbers become [re, im]; non-finite floats become null."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(asdict(obj))
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, complex | np.complexfloating):
        return [to_jsonable(float(obj.real)), to_jsonable(float(obj.imag))]
    if isinstance(obj, np.bool_ | bool):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def emit_json(obj: Any) -> None:
    """Print one JSON object on stdout."""
    typer.echo(json.dumps(to_jsonable(obj), indent=2))


def parse_range(text: str, name: str = "range") -> tuple[float, float]:
    """'a:b' -> (a, b), with a clear error."""
    try:
        a, b = (float(t) for t in text.split(":"))
    except ValueError:
        raise UserError(f"{name} '{text}': expected FROM:TO, e.g. 1e-4:8e-4") from None
    return a, b


def output_path(out: Path | None, default: str) -> Path:
    """The output path (creating its folder): ``out`` if given, else ``default``."""
    path = Path(out) if out is not None else Path(default)
    if path.suffix == "":
        path.mkdir(parents=True, exist_ok=True)
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    return path
