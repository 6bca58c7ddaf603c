"""`maglev-match explore` without a browser: the server's endpoints answer what the API
computes, refuse bad values with the command line's own messages and compute nothing then,
drop stale requests, refuse other hosts and other addresses, survive a client that leaves
mid-computation and a computation that crashes, export what reproduces the view, and the
background job is cancelled for real. (The page itself: tests/test_explore_browser.py.)"""

from __future__ import annotations

import io
import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
import tomllib
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import xarray as xr

from maglev_match import api
from maglev_match.cli import main
from maglev_match.core.params import available_presets, load_params, load_preset, valid_range
from maglev_match.explore.inputs import CONTROLS, State, params_of, parse_query
from maglev_match.explore.server import ExploreServer

DESIGN = "preset=turnout-soft&EI=2.2e10&kD=140"


@pytest.fixture(scope="module")
def server():
    s = ExploreServer("turnout-soft", "unit", port=0).start()
    yield s
    s.stop()


def _get(server, path, method="GET", headers=None, timeout=300):
    req = urllib.request.Request(f"http://127.0.0.1:{server.port}{path}", method=method,
                                 headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def _json(server, path, method="GET"):
    code, body = _get(server, path, method)
    return code, json.loads(body)


# ----- inputs -----------------------------------------------------------------------------
def test_slider_windows_lie_in_the_valid_ranges_and_span_the_presets():
    for c in CONTROLS:
        lo, hi = valid_range(c.name)
        assert lo <= c.low < c.high <= hi, c.name
        assert not c.log or c.low > 0, c.name
    for name in available_presets():
        p = load_preset(name)
        for c in CONTROLS:
            assert c.low <= getattr(p, c.name) <= c.high, (name, c.name)


@pytest.mark.parametrize("text", ["kD=-1", "kD=inf", "kD=nan", "EI=1e20", "kD=abc",
                                  "tau=2", "sigma=0"])
def test_a_refused_value_carries_the_command_lines_message(text, capsys):
    name, raw = text.split("=")
    state, errors = parse_query({"preset": "turnout-soft", name: raw})
    assert name not in state.overrides and set(errors) == {name}
    code = main(["index", "--set", text])
    err = capsys.readouterr().err
    assert code == 2
    # the command line prints the same sentence (field, value, rule)
    assert errors[name].split(": ", 1)[1] in " ".join(err.split())


def test_a_state_round_trips_through_its_query():
    state, errors = parse_query({"preset": "turnout-stiff", "EI": "2.2e10", "kD": "140"})
    assert not errors
    again, errors = parse_query(state.query())
    assert again == state and not errors
    assert params_of(again).EI == 2.2e10


# ----- endpoints ----------------------------------------------------------------------------
def test_the_page_and_its_scripts_are_served_by_the_package(server):
    code, page = _get(server, "/")
    assert code == 200
    text = page.decode()
    assert "http://" not in text and "https://" not in text  # no CDN
    for path in ("/static/explore.js", "/static/explore.css",
                 "/static/vendor/uPlot.iife.min.js", "/static/vendor/uPlot.min.css"):
        assert path in text
        assert _get(server, path)[0] == 200


def test_release_gives_the_index_of_the_api_and_quick_the_stability(server):
    code, q = _json(server, f"/api/quick?{DESIGN}&seq=1")
    assert code == 200
    st = api.stability("turnout-soft", EI=2.2e10, kD=140.0)
    assert q["stable"] == st.stable and math.isclose(q["margin"], st.margin, rel_tol=1e-9)
    code, r = _json(server, f"/api/release?{DESIGN}&seq=2")
    assert code == 200, r
    direct = api.matching_index("turnout-soft", EI=2.2e10, kD=140.0, stage=False)
    assert f"{r['index']['chi']:.3f}" == f"{direct.chi:.3f}"
    # the drawn cycle (the orbit evaluated, the gap of the model) reaches the analysis's
    # largest gap deviation of the cycle, h of the paper's definition
    assert math.isclose(max(r["cycle"]["gap_deviation"]), direct.cycle_gap_max, rel_tol=1e-3)
    # the critical run is drawn just below the critical size: it does not collide
    assert r["run"]["outcome"] != "collision"
    assert r["run"]["size"] < r["run"]["critical_size"]
    # the next release is warm-started from this one and agrees with a direct computation
    code, r2 = _json(server, "/api/release?preset=turnout-soft&EI=2.25e10&kD=140&seq=3")
    assert r2["warm_start"] == "continued from the previous design"
    direct2 = api.matching_index("turnout-soft", EI=2.25e10, kD=140.0, stage=False)
    assert f"{r2['index']['chi']:.3f}" == f"{direct2.chi:.3f}"


def test_a_bad_value_is_refused_and_nothing_is_computed(server):
    before = server.session.last_index()
    for tier in ("quick", "release"):
        code, r = _json(server, f"/api/{tier}?preset=turnout-soft&kD=-5&seq=7")
        assert code == 400 and "kD" in r["errors"] and ">= 0" in r["errors"]["kD"]
    code, r = _json(server, "/api/init?preset=turnout-soft&EI=inf")
    assert r["errors"]["EI"].startswith("parameter 'EI' = inf")
    assert server.session.last_index() is before


def test_a_request_behind_a_newer_one_is_answered_stale(server):
    code, r = _json(server, "/api/quick?preset=turnout-soft&seq=1000")
    assert code == 200 and not r.get("stale") and r["seq"] == 1000
    code, r = _json(server, "/api/quick?preset=turnout-soft&kD=141&seq=999")
    assert r == {"seq": 999, "stale": True}
    # the numbers are a page's own: another page (a reload, a second tab) starts again
    code, r = _json(server, "/api/quick?preset=turnout-soft&kD=141&seq=1&client=tab2")
    assert code == 200 and not r.get("stale") and r["seq"] == 1


def test_another_host_name_is_refused(server):
    code, body = _get(server, "/api/init", headers={"Host": f"evil.example:{server.port}"})
    assert code == 403 and b"refused" in body
    code, _ = _get(server, "/static/explore.js", headers={"Host": "evil.example"})
    assert code == 403
    assert _get(server, "/api/init", headers={"Host": f"localhost:{server.port}"})[0] == 200


def _outside_address() -> str | None:
    """An address of this machine that is not loopback (None if it has none)."""
    for target in ("10.255.255.255", "192.0.2.1"):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.connect((target, 1))  # UDP: no packet is sent
                ip = s.getsockname()[0]
            except OSError:
                continue
        if not ip.startswith("127.") and ip != "0.0.0.0":
            return ip
    return None


def test_the_server_refuses_connections_to_other_addresses(server):
    ip = _outside_address()
    if ip is None:
        pytest.skip("this machine has no non-loopback address to connect to")
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((ip, server.port), timeout=10)


def test_the_server_survives_a_client_that_leaves_mid_computation(server):
    with socket.create_connection(("127.0.0.1", server.port)) as s:
        s.sendall(f"GET /api/release?preset=turnout-soft&kD=150&EI=2.1e10&seq=2000 HTTP/1.1"
                  f"\r\nHost: 127.0.0.1:{server.port}\r\n\r\n".encode())
        time.sleep(0.2)
    code, r = _json(server, "/api/release?preset=turnout-soft&kD=150&seq=2001")
    assert code == 200 and r["seq"] == 2001 and r["index"]["chi"] > 0


def test_a_crashing_computation_is_an_error_and_the_server_goes_on(server, monkeypatch):
    def boom(state):
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(server.session, "release", boom)
    code, r = _json(server, "/api/release?preset=turnout-soft&seq=3000")
    assert code == 500 and "simulated failure" in r["error"]
    monkeypatch.undo()
    assert _json(server, "/api/quick?preset=turnout-soft&seq=3001")[0] == 200


def test_the_exports_reproduce_the_view(server, tmp_path):
    _json(server, f"/api/release?{DESIGN}&seq=4000")
    code, cmd = _get(server, f"/api/export/command?{DESIGN}")
    assert cmd.decode().split() == ["maglev-match", "index", "--preset", "turnout-soft",
                                    "--model", "unit", "--set", "EI=22000000000.0", "--set",
                                    "kD=140.0"]
    code, toml = _get(server, f"/api/export/toml?{DESIGN}")
    f = tmp_path / "design.toml"
    f.write_bytes(toml)
    tomllib.loads(toml.decode())
    assert load_params(None, f) == params_of(State("turnout-soft", (("EI", 2.2e10),
                                                                    ("kD", 140.0))))
    code, text = _get(server, f"/api/export/csv?what=run&{DESIGN}")
    lines = text.decode().splitlines()
    assert code == 200 and lines[0] == "t_s,gap_m,current_A" and len(lines) > 100
    code, png = _get(server, f"/api/export/png?what=index&{DESIGN}")
    assert code == 200 and png.startswith(b"\x89PNG")
    code, svg = _get(server, f"/api/export/svg?what=run&{DESIGN}")
    assert code == 200 and b"<svg" in svg[:500]
    # netCDF: the result objects' own .to_xarray()
    code, body = _json(server, f"/api/release?{DESIGN}&seq=4001")
    code, nc = _get(server, "/api/export/netcdf?what=index")
    ds = xr.open_dataset(io.BytesIO(nc), engine="h5netcdf")
    assert code == 200 and float(ds["chi"]) == body["index"]["chi"]
    code, nc = _get(server, "/api/export/netcdf?what=run")
    run = xr.open_dataset(io.BytesIO(nc), engine="h5netcdf")
    assert code == 200 and run.sizes["time"] == len(body["run"]["t"])
    assert _get(server, "/api/export/netcdf?what=nothing")[0] == 404


def test_a_background_job_is_cancelled_for_real_and_the_next_one_runs(server):
    code, job = _json(server, "/api/job?kind=hopf_curve&preset=turnout-soft&seq=1", "POST")
    assert job["status"] == "running"
    proc = server.jobs.process
    code, job = _json(server, f"/api/job/{job['id']}/cancel", "POST")
    assert job["status"] == "cancelled"
    assert not proc.is_alive()
    code, job = _json(server, "/api/job?kind=hopf_curve&preset=turnout-soft&seq=2", "POST")
    deadline = time.monotonic() + 600
    while job["status"] == "running" and time.monotonic() < deadline:
        time.sleep(0.5)
        job = _json(server, f"/api/job/{job['id']}")[1]
    assert job["status"] == "done", job
    res = job["result"]
    assert res["names"] == ["omega1", "sigma"] and res["branches"]
    # the same curve as the API computes in this process
    curves = api.hopf_curve("turnout-soft")
    assert len(res["branches"]) == len(curves)
    assert math.isclose(res["design"][0], load_preset("turnout-soft").omega1)
    # its netCDF: the first branch's dataset, one entry per point of the curve
    code, nc = _get(server, "/api/export/netcdf?what=hopf_curve")
    ds = xr.open_dataset(io.BytesIO(nc), engine="h5netcdf")
    assert code == 200 and len(res["branches"][0]["x"]) in ds.sizes.values()


# ----- the command ----------------------------------------------------------------------
@pytest.mark.parametrize("args, option", [(["--port", "70000"], "--port"),
                                          (["--preset", "nope"], "--preset"),
                                          (["--model", "car"], "--model"),
                                          (["--set", "kD=-1"], "kD"),
                                          (["--set", "sigma=0"], "sigma")])
def test_explore_refuses_bad_options(args, option, capsys):
    code = main(["explore", "--no-browser", *args])
    assert code == 2
    assert option in capsys.readouterr().err


def test_explore_serves_prints_its_address_and_stops_on_ctrl_c():
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")}
    proc = subprocess.Popen([sys.executable, "-m", "maglev_match", "explore", "--no-browser",
                             "--port", "0", "--set", "EI=2.2e10"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    try:
        line = proc.stdout.readline()
        assert "http://127.0.0.1:" in line, line
        url = line.split()[2]
        base = url.split("/?")[0]
        # the page opens on the design of --preset and --set
        assert url.endswith("/?preset=turnout-soft&EI=22000000000.0"), url
        with urllib.request.urlopen(base + "/api/init?preset=turnout-soft", timeout=60) as r:
            assert json.loads(r.read())["model"] == "unit"
        os.killpg(proc.pid, signal.SIGINT)
        code = proc.wait(60)
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert code == 130 and "stopped" in err and "Traceback" not in err
