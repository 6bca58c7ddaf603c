"""The explorer's web server (tornado): one static page, JSON endpoints, exports.

Bound to 127.0.0.1 by default; every request's Host header must name the address the
server is bound to (or ``localhost``), so that a web page elsewhere cannot reach it through
DNS rebinding. Computations run on one worker thread of the server process (the kernels
stay compiled); the background tier runs in a child process (:mod:`.jobs`).

Every computing request carries a sequence number ``seq``; a request that waits behind a
newer one of its kind is answered ``{"stale": true}`` without computing (latest request
wins), and the page drops any answer older than what it shows."""

from __future__ import annotations

import asyncio
import csv
import io
import json
import threading
from concurrent.futures import ThreadPoolExecutor
from importlib import resources
from typing import Any
from urllib.parse import urlencode

import tornado.httpserver
import tornado.netutil
import tornado.web

from maglev_match.core.params import DEFAULT_PRESET, ParameterError, available_presets
from maglev_match.explore.background import KINDS, check_speed
from maglev_match.explore.inputs import (
    State,
    command_line,
    controls_json,
    params_of,
    parse_query,
    toml_text,
)
from maglev_match.explore.jobs import JobRunner
from maglev_match.explore.session import Session, finite

__all__ = ["ExploreServer", "LOOPBACK", "STATIC"]

LOOPBACK = ("127.0.0.1", "localhost", "::1")
STATIC = resources.files("maglev_match") / "explore" / "static"


class _Base(tornado.web.RequestHandler):
    server: ExploreServer

    def initialize(self, server: ExploreServer) -> None:
        self.server = server
        self.gone = False

    def prepare(self) -> None:
        host = self.request.host_name.strip("[]").lower()
        if host not in self.server.allowed_hosts:
            self.set_status(403)
            self.finish({"error": f"host '{self.request.host}' refused: this server answers "
                                  f"only requests addressed to {self.server.host}"})

    def on_connection_close(self) -> None:
        self.gone = True

    def set_default_headers(self) -> None:
        self.set_header("Cache-Control", "no-store")
        self.set_header("X-Content-Type-Options", "nosniff")

    def query(self) -> dict[str, str]:
        return {k: self.get_argument(k) for k in self.request.arguments}

    def seq(self) -> int:
        try:
            return int(self.get_argument("seq", "0"))
        except ValueError:
            return 0

    def send(self, data: Any, status: int = 200) -> None:
        if self.gone:  # the client went away mid-computation: nothing to answer
            return
        self.set_status(status)
        self.set_header("Content-Type", "application/json")
        self.finish(json.dumps(finite(data), allow_nan=False))

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        exc = kwargs.get("exc_info", (None, None, None))[1]
        self.set_header("Content-Type", "application/json")
        self.finish(json.dumps({"error": f"{type(exc).__name__}: {exc}" if exc else
                                self._reason}))


class PageHandler(_Base):
    def get(self) -> None:
        self.set_header("Content-Type", "text/html; charset=utf-8")
        self.finish((STATIC / "index.html").read_bytes())


class NoIconHandler(_Base):
    def get(self) -> None:
        self.set_status(204)
        self.finish()


class InitHandler(_Base):
    def get(self) -> None:
        state, errors = parse_query(self.query())
        self.send({"model": self.server.session.model, "presets": available_presets(),
                   "state": state.query(), "errors": errors,
                   "controls": controls_json(state)})


class ComputeHandler(_Base):
    """``/api/quick`` and ``/api/release``: one tier of the state in the query."""

    def initialize(self, server: ExploreServer, tier: str) -> None:  # type: ignore[override]
        super().initialize(server)
        self.tier = tier

    async def get(self) -> None:
        seq = self.seq()
        state, errors = parse_query(self.query())
        if errors:  # the command line's messages; nothing computed
            self.send({"seq": seq, "errors": errors}, 400)
            return
        key = (self.get_argument("client", ""), self.tier)
        self.server.note_latest(key, seq)
        try:
            data = await self.server.run(key, seq, state)
        except ParameterError as e:
            self.send({"seq": seq, "errors": {str(e.field): str(e)}}, 400)
            return
        except Exception as e:  # noqa: BLE001 - shown in the page; the server keeps serving
            self.send({"seq": seq, "error": f"{type(e).__name__}: {e}"}, 500)
            return
        if data is None:
            self.send({"seq": seq, "stale": True})
            return
        self.send({"seq": seq, "state": state.query(), **data})


class JobHandler(_Base):
    """``POST /api/job?kind=K&...`` starts a background job (cancelling the one running),
    ``GET /api/job/ID`` polls it, ``POST /api/job/ID/cancel`` cancels it. Starting and
    ending the child process run off the server's event loop."""

    async def post(self, job_id: str | None = None, action: str | None = None) -> None:
        runner = self.server.jobs
        if job_id is None:
            state, errors = parse_query(self.query())
            if errors:
                self.send({"errors": errors}, 400)
                return
            kind = self.get_argument("kind", "hopf_curve")
            extra = {}
            if kind == "speed":  # the page's speed (km/h), checked before anything starts
                raw = self.get_argument("v", "0")
                try:
                    v = float(raw)
                except ValueError:
                    v = None
                try:
                    if v is None:
                        raise ParameterError("v", raw, "must be a number (km/h)")
                    extra["v"] = check_speed(v)
                except ParameterError as e:
                    self.send({"errors": {"v": str(e)}}, 400)
                    return
            try:
                job = await asyncio.to_thread(runner.start, kind, state, self.seq(), **extra)
            except KeyError:
                self.send({"error": f"no background job '{kind}'"}, 400)
                return
            self.send(job.as_json())
            return
        if action == "cancel":
            job = await asyncio.to_thread(runner.cancel, int(job_id))
        else:
            job = runner.poll(int(job_id))
        if job is None:
            self.send({"error": f"no job {job_id}"}, 404)
        else:
            self.send(job.as_json())

    def get(self, job_id: str, action: str | None = None) -> None:
        job = self.server.jobs.poll(int(job_id))
        if job is None:
            self.send({"error": f"no job {job_id}"}, 404)
        else:
            self.send(job.as_json())


class ExportHandler(_Base):
    """``/api/export/KIND``: command, toml, csv (what=cycle|run), png or svg (what=index|
    run: the product's figure through the result's ``.plot()``), netcdf (what=index|run|
    hopf_curve|tile|speed|cycle_branch: the result object's ``.to_xarray()``)."""

    async def get(self, kind: str) -> None:
        state, errors = parse_query(self.query())
        if errors:
            self.send({"errors": errors}, 400)
            return
        model = self.server.session.model
        if kind == "command":
            self._text(command_line(state, model) + "\n", "text/plain", "command.txt")
        elif kind == "toml":
            self._text(toml_text(state, model), "application/toml", "design.toml")
        elif kind == "csv":
            what = self.get_argument("what", "cycle")
            rows = self.server.curves.get(what)
            if rows is None:
                self.send({"error": f"no {what} curve yet: release a design first"}, 404)
                return
            buf = io.StringIO()
            w = csv.writer(buf)
            w.writerow(rows["header"])
            w.writerows(zip(*rows["columns"], strict=True))
            self._text(buf.getvalue(), "text/csv", f"{what}.csv")
        elif kind == "netcdf":
            await self._netcdf(self.get_argument("what", "index"))
        elif kind in ("png", "svg"):
            what = self.get_argument("what", "index")
            loop = asyncio.get_running_loop()
            try:
                data = await loop.run_in_executor(self.server.executor,
                                                  self.server.session.figure, what, kind)
            except LookupError as e:
                self.send({"error": str(e)}, 404)
                return
            self.set_header("Content-Type", "image/png" if kind == "png" else "image/svg+xml")
            self.set_header("Content-Disposition", f'attachment; filename="{what}.{kind}"')
            self.finish(data)
        else:
            self.send({"error": f"no export '{kind}'"}, 404)

    async def _netcdf(self, what: str) -> None:
        """The result object's ``.to_xarray()`` as netCDF-4: the last release's index or
        critical run, or the last finished background job of a kind."""
        if what in ("index", "run"):
            loop = asyncio.get_running_loop()
            try:
                data = await loop.run_in_executor(self.server.executor,
                                                  self.server.session.netcdf, what)
            except LookupError as e:
                self.send({"error": str(e)}, 404)
                return
        elif what in KINDS:
            job = await asyncio.to_thread(self.server.jobs.latest, what)
            data = None if job is None else job.netcdf
            if data is None:
                self.send({"error": f"no {what} result yet: run it first"}, 404)
                return
        else:
            self.send({"error": f"no netCDF export '{what}'"}, 404)
            return
        self.set_header("Content-Type", "application/x-netcdf")
        self.set_header("Content-Disposition", f'attachment; filename="{what}.nc"')
        self.finish(data)

    def _text(self, text: str, ctype: str, name: str) -> None:
        self.set_header("Content-Type", f"{ctype}; charset=utf-8")
        self.set_header("Content-Disposition", f'attachment; filename="{name}"')
        self.finish(text)


class ExploreServer:
    """The explorer: ``start()`` serves in a background thread (``url`` then answers),
    ``stop()`` ends it."""

    def __init__(self, preset: str = DEFAULT_PRESET, model: str = "unit",
                 host: str = "127.0.0.1", port: int = 0,
                 overrides: dict[str, float] | None = None) -> None:
        if preset not in available_presets():
            raise ParameterError("--preset", preset, "no such preset; available: "
                                 + ", ".join(available_presets()))
        self.preset, self.host, self.port = preset, host, port
        self.start_state = State(preset, tuple((overrides or {}).items()))
        params_of(self.start_state)  # refused before serving
        self.session = Session(model)
        self.jobs = JobRunner(self.session.model)
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="explore")
        #: (client, tier) -> the newest sequence number received (a page is one client: its
        #: numbers start again at a reload, in a second tab)
        self.latest: dict[tuple[str, str], int] = {}
        self.curves: dict[str, dict[str, Any]] = {}
        self.allowed_hosts = {h.lower() for h in LOOPBACK} | {host.strip("[]").lower()}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?{urlencode(self.start_state.query())}"

    def app(self) -> tornado.web.Application:
        kw = {"server": self}
        return tornado.web.Application([
            (r"/", PageHandler, kw),
            (r"/favicon.ico", NoIconHandler, kw),
            (r"/api/init", InitHandler, kw),
            (r"/api/quick", ComputeHandler, {**kw, "tier": "quick"}),
            (r"/api/release", ComputeHandler, {**kw, "tier": "release"}),
            (r"/api/job", JobHandler, kw),
            (r"/api/job/(\d+)", JobHandler, kw),
            (r"/api/job/(\d+)/(cancel)", JobHandler, kw),
            (r"/api/export/(\w+)", ExportHandler, kw),
            (r"/static/(.*)", _Static, {"path": str(STATIC), "server": self}),
        ], compress_response=True)

    def note_latest(self, key: tuple[str, str], seq: int) -> None:
        if key not in self.latest and len(self.latest) > 1000:  # forget old pages
            self.latest.clear()
        self.latest[key] = max(self.latest.get(key, seq), seq)

    async def run(self, key: tuple[str, str], seq: int, state: State
                  ) -> dict[str, Any] | None:
        """Compute one tier (``key``: the client and the tier) on the worker thread; None
        when a newer request of the same client and tier arrived before this one started
        (stale, not computed)."""
        def work() -> dict[str, Any] | None:
            if seq < self.latest.get(key, seq):
                return None
            if key[1] == "quick":
                return self.session.quick(state)
            data = self.session.release(state)
            self._keep_curves(data)
            return data

        return await asyncio.get_running_loop().run_in_executor(self.executor, work)

    def _keep_curves(self, data: dict[str, Any]) -> None:
        cyc, run = data.get("cycle"), data.get("run")
        if cyc:
            self.curves["cycle"] = {"header": ["t_s", "gap_deviation_m"],
                                    "columns": [cyc["t"], cyc["gap_deviation"]]}
        if run:
            self.curves["run"] = {"header": ["t_s", "gap_m", "current_A"],
                                  "columns": [run["t"], run["gap"], run["current"]]}

    # ----- life cycle -------------------------------------------------------------------
    def start(self) -> ExploreServer:
        self._thread = threading.Thread(target=self._serve, name="explore-server",
                                        daemon=True)
        self._thread.start()
        self._ready.wait(30)
        if self._error is not None:
            raise self._error
        return self

    def _serve(self) -> None:
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        self._loop = loop
        try:
            sockets = tornado.netutil.bind_sockets(self.port, self.host)
        except OSError as e:
            self._error = e
            self._ready.set()
            return
        self.port = sockets[0].getsockname()[1]
        server = tornado.httpserver.HTTPServer(self.app())
        server.add_sockets(sockets)
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            server.stop()
            loop.run_until_complete(server.close_all_connections())
            loop.close()

    def stop(self) -> None:
        if self._loop is not None and self._loop.is_running():
            self._loop.call_soon_threadsafe(self._loop.stop)
        if self._thread is not None:
            self._thread.join(10)
        self.jobs.close()
        self.executor.shutdown(wait=False, cancel_futures=True)


class _Static(tornado.web.StaticFileHandler):
    def initialize(self, path: str, server: ExploreServer) -> None:  # type: ignore[override]
        super().initialize(path)
        self.server = server

    def prepare(self) -> None:
        host = self.request.host_name.strip("[]").lower()
        if host not in self.server.allowed_hosts:
            raise tornado.web.HTTPError(403)
