"""The explorer's background tier: long computations (the kinds of :mod:`.background`:
the Hopf curve, the map tile, the speed sweep, the cycle branch) in one long-lived child
process, with progress lines and a cancel that really stops the work (the child is
terminated; a fresh one starts on the next job).

The child keeps its compiled kernels between jobs. One job runs at a time: starting a job
cancels the running or waiting one of the same kind (the page only shows the latest
design's curve); a job of another kind waits ("queued") until the running one ends."""

from __future__ import annotations

import itertools
import multiprocessing as mp
import queue
import threading
from dataclasses import dataclass, field
from typing import Any

from maglev_match.explore.background import KINDS, NETCDF, hopf_curve_job
from maglev_match.explore.inputs import State, params_of

__all__ = ["JobRunner", "Job", "KINDS", "hopf_curve_job"]


def _worker(tasks: Any, events: Any) -> None:  # pragma: no cover - runs in the child
    """The child process: run each task, sending progress, the result or the error."""
    while True:
        task = tasks.get()
        if task is None:
            return
        job_id, kind, preset, values, model, extra = task

        def say(text: str, job_id=job_id) -> None:
            events.put((job_id, "progress", str(text)))

        try:
            params = params_of(State(preset, tuple(values)))
            events.put((job_id, "done", KINDS[kind](params, model, say, **extra)))
        except Exception as e:  # noqa: BLE001 - reported to the page, the child lives on
            events.put((job_id, "error", f"{type(e).__name__}: {e}"))


@dataclass
class Job:
    """One background job and what is known of it."""

    id: int
    kind: str
    seq: int
    status: str = "queued"  # queued, running, done, error, cancelled
    progress: list[str] = field(default_factory=list)
    result: Any = None
    error: str | None = None
    #: the result as a netCDF file (bytes; not sent with the JSON)
    netcdf: bytes | None = field(default=None, repr=False)
    #: the child process that ran it (its exit code tells a cancel ended it)
    process: Any = field(default=None, repr=False)
    task: tuple = field(default=(), repr=False)

    def as_json(self) -> dict[str, Any]:
        return {"id": self.id, "kind": self.kind, "seq": self.seq, "status": self.status,
                "progress": list(self.progress[-20:]), "result": self.result,
                "error": self.error}


class JobRunner:
    """Runs :data:`KINDS` jobs in one child process (spawned on first use, kept warm)."""

    def __init__(self, model: str) -> None:
        self.model = model
        self._ctx = mp.get_context("spawn")
        self._proc: Any = None
        self._tasks: Any = None
        self._events: Any = None
        self._ids = itertools.count(1)
        self._jobs: dict[int, Job] = {}
        self._running: Job | None = None
        self._lock = threading.Lock()

    @property
    def process(self) -> Any:
        """The child process running the jobs (None before the first job, after a
        cancel)."""
        return self._proc

    def _ensure(self) -> None:
        if self._proc is not None and self._proc.is_alive():
            return
        self._tasks, self._events = self._ctx.Queue(), self._ctx.Queue()
        self._proc = self._ctx.Process(target=_worker, args=(self._tasks, self._events),
                                       daemon=True, name="maglev-match-explore-worker")
        self._proc.start()

    def start(self, kind: str, state: State, seq: int, **extra: Any) -> Job:
        """Start a job, cancelling the running or waiting one of the same kind; while a
        job of another kind runs it waits ("queued") and starts when that one ends."""
        if kind not in KINDS:
            raise KeyError(kind)
        with self._lock:
            self._drain()
            for job in list(self._jobs.values()):
                if job.kind == kind and job.status in ("running", "queued"):
                    self._cancel_locked(job)
            job = Job(next(self._ids), kind, seq, status="queued")
            job.task = (job.id, kind, state.preset, list(state.values), self.model, extra)
            self._jobs[job.id] = job
            self._dispatch()
            return job

    def job(self, job_id: int) -> Job | None:
        """The job as last seen (no events applied)."""
        return self._jobs.get(job_id)

    def poll(self, job_id: int) -> Job | None:
        """The job with every event received so far applied."""
        with self._lock:
            self._drain()
            return self._jobs.get(job_id)

    def latest(self, kind: str) -> Job | None:
        """The newest finished job of a kind (its result and netCDF)."""
        with self._lock:
            self._drain()
            done = [j for j in self._jobs.values() if j.kind == kind and j.status == "done"]
            return max(done, key=lambda j: j.id) if done else None

    def cancel(self, job_id: int) -> Job | None:
        with self._lock:
            self._drain()
            job = self._jobs.get(job_id)
            if job is not None and job.status in ("running", "queued"):
                self._cancel_locked(job)
            self._dispatch()
            return job

    def _cancel_locked(self, job: Job) -> None:
        """A waiting job leaves the queue; a running one stops with the child (the
        computation with it): the next job starts a fresh child."""
        was_running = job.status == "running"
        job.status = "cancelled"
        job.progress.append("cancelled")
        if was_running and self._proc is not None:
            self._proc.terminate()
            self._proc.join(5)
            if self._proc.is_alive():  # pragma: no cover - terminate ignored
                self._proc.kill()
                self._proc.join(5)
            self._proc = None
            self._running = None

    def _dispatch(self) -> None:
        """Hand the oldest waiting job to the child when none runs."""
        if self._running is not None:
            return
        waiting = sorted((j for j in self._jobs.values() if j.status == "queued"),
                         key=lambda j: j.id)
        if not waiting:
            return
        job = waiting[0]
        self._ensure()
        job.status, job.process = "running", self._proc
        self._running = job
        self._tasks.put(job.task)

    def _drain(self) -> None:
        if self._events is not None:
            while True:
                try:
                    job_id, what, payload = self._events.get_nowait()
                except (queue.Empty, OSError, EOFError, ValueError):
                    break
                job = self._jobs.get(job_id)
                if job is None or job.status != "running":
                    continue
                if what == "progress":
                    job.progress.append(payload)
                    continue
                if what == "done":
                    job.netcdf = payload.pop(NETCDF, None)
                    job.status, job.result = "done", payload
                else:
                    job.status, job.error = "error", payload
                if self._running is job:
                    self._running = None
        if self._proc is not None and not self._proc.is_alive():
            for job in self._jobs.values():
                if job.status == "running":
                    job.status, job.error = "error", "the background process ended"
            self._proc, self._running = None, None
        self._dispatch()

    def close(self) -> None:
        with self._lock:
            if self._proc is not None:
                self._proc.terminate()
                self._proc.join(5)
                self._proc = None
            self._running = None
