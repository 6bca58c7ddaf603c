"""`maglev-match explore`: the design explorer in the browser (a local web server)."""

from __future__ import annotations

import ipaddress
import time
from typing import Annotated

import typer

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    ConfigOpt,
    ModelOpt,
    SetOpt,
    check_index_params,
    check_model,
    console,
    params_from_options,
)
from maglev_match.cli.models import is_model_file, refuse_model_file
from maglev_match.core.params import (
    FIELD_NAMES,
    ParameterError,
    available_presets,
    load_toml,
    parse_assignment,
)

#: API keyword -> option. The explorer computes through `matching_index` and `stability`
#: with the model of --model and the design of --preset, --config and --set (its first
#: state: the page's URL); --host, --port and --no-browser only say where and how the page
#: is served.
EXPLORE_OPTIONS = {"model": "--model", "params": "--preset"}


def _is_loopback(host: str) -> bool:
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _port(value: int) -> int:
    if not 0 <= value <= 65535:
        raise typer.BadParameter(f"{value}: must be a TCP port from 0 to 65535 (0: any free "
                                 "port)")
    return value


@app.command("explore")
def explore_command(
    preset: Annotated[str, typer.Option(
        "--preset", help="Shipped parameter preset the page opens on.")] = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    port: Annotated[int, typer.Option("--port", help="TCP port (0: any free port).",
                                      callback=_port)] = 8765,
    host: Annotated[str, typer.Option(
        "--host", help="Address to bind (default 127.0.0.1: this machine only; another "
        "address serves the page to the network, with a warning).")] = "127.0.0.1",
    no_browser: Annotated[bool, typer.Option(
        "--no-browser", help="Do not open the page in the browser.")] = False,
) -> None:
    """The design explorer in the browser: a local web page with the beam, gains and delay
    on sliders, the stability margin live, the headline index on release (warm-started from
    the previous design), the basin-bounding cycle, the critical run and the Hopf curve;
    stops with Ctrl-C.

    The page opens on --preset with the values of --config and --set (its address carries
    them: ?preset=turnout-soft&EI=2.2e10)."""
    if is_model_file(model):
        refuse_model_file(model, "explore")
    model = check_model(model)
    if preset not in available_presets():
        raise ParameterError("--preset", preset, "no such preset; available: "
                             + ", ".join(available_presets()))
    params = params_from_options(preset, config, set_)  # the command line's checks
    check_index_params(params)
    given = set(load_toml(config)) if config is not None else set()
    given |= {parse_assignment(s)[0] for s in set_ or []}
    overrides = {n: getattr(params, n) for n in FIELD_NAMES if n in given}
    if not _is_loopback(host):
        console.print(f"[yellow]warning:[/] serving on {host}: the explorer is reachable from "
                      "other machines on that network, without authentication",
                      highlight=False)
    from maglev_match.explore.server import ExploreServer

    server = ExploreServer(preset=preset, model=model, host=host, port=port,
                           overrides=overrides)
    try:
        server.start()
    except OSError as e:
        raise ParameterError("--port", port, f"cannot listen on {host}:{port} ({e.strerror or e})"
                             ) from None
    try:
        console.print(f"maglev-match explore: {server.url}  (Ctrl-C stops)", highlight=False,
                      soft_wrap=True)
        if not no_browser:
            import webbrowser

            webbrowser.open(server.url)
        while True:
            time.sleep(0.5)
    finally:
        server.stop()
