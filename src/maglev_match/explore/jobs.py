"""The explorer's background tier: long computations (the Hopf curve in the design plane)
in one long-lived child process, with progress lines and a cancel that really stops the
work (the child is terminated; a fresh one starts on the next job).

The child keeps its compiled kernels between jobs. One job runs at a time: starting a new
job cancels the one running (the page only shows the latest design's curve)."""

from __future__ import annotations

import itertools
import multiprocessing as mp
import queue
import threading
from dataclasses import dataclass, field
from typing import Any

from maglev_match.explore.inputs import State, params_of

__all__ = ["JobRunner", "Job", "KINDS", "hopf_curve_job"]


def hopf_curve_job(params: Any, model: str, say) -> dict[str, Any]:
    """The Hopf curve(s) in the model's default plane (`api.hopf_curve`), as JSON-ready
    branches: the two parameters along each branch, l1 along it (l1 > 0 subcritical,
    drawn dashed; l1 < 0 supercritical, solid), and its codimension-two points with their
    AUTO/MatCont labels."""
    import numpy as np

    from maglev_match import api

    say("continuing the Hopf curve ...")
    curves = api.hopf_curve(params, model=model, stage=say)
    branches = []
    for c in curves:
        vals = np.asarray(c.values(), float)
        branches.append({
            "params": list(c.params), "x": vals[:, 0].tolist(), "y": vals[:, 1].tolist(),
            "l1": np.asarray(c.l1(), float).tolist(), "converged": bool(c.converged),
            "message": c.message,
            "special": [{"label": sp.label, "type": str(sp.type),
                         "x": float(sp.values[0]), "y": float(sp.values[1])}
                        for sp in c.special_points if getattr(sp, "values", None) is not None],
        })
    names = branches[0]["params"] if branches else []
    design = [float(getattr(params, n)) for n in names] if names else []
    return {"branches": branches, "names": names, "design": design}


#: the kinds of background job: name -> function(params, model, say) -> JSON-ready dict
KINDS = {"hopf_curve": hopf_curve_job}


def _worker(tasks: Any, events: Any) -> None:  # pragma: no cover - runs in the child
    """The child process: run each task, sending progress, the result or the error."""
    while True:
        task = tasks.get()
        if task is None:
            return
        job_id, kind, preset, values, model = task

        def say(text: str, job_id=job_id) -> None:
            events.put((job_id, "progress", str(text)))

        try:
            params = params_of(State(preset, tuple(values)))
            events.put((job_id, "done", KINDS[kind](params, model, say)))
        except Exception as e:  # noqa: BLE001 - reported to the page, the child lives on
            events.put((job_id, "error", f"{type(e).__name__}: {e}"))


@dataclass
class Job:
    """One background job and what is known of it."""

    id: int
    kind: str
    seq: int
    status: str = "running"  # running, done, error, cancelled
    progress: list[str] = field(default_factory=list)
    result: Any = None
    error: str | None = None

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

    def start(self, kind: str, state: State, seq: int) -> Job:
        """Start a job (cancelling the one running)."""
        if kind not in KINDS:
            raise KeyError(kind)
        with self._lock:
            for job in self._jobs.values():
                if job.status == "running":
                    self._cancel_locked(job)
            self._ensure()
            job = Job(next(self._ids), kind, seq)
            self._jobs[job.id] = job
            self._tasks.put((job.id, kind, state.preset, list(state.values), self.model))
            return job

    def poll(self, job_id: int) -> Job | None:
        """The job with every event received so far applied."""
        with self._lock:
            self._drain()
            return self._jobs.get(job_id)

    def cancel(self, job_id: int) -> Job | None:
        with self._lock:
            self._drain()
            job = self._jobs.get(job_id)
            if job is not None and job.status == "running":
                self._cancel_locked(job)
            return job

    def _cancel_locked(self, job: Job) -> None:
        """Stop the child (the computation with it); the next job starts a fresh one."""
        job.status = "cancelled"
        job.progress.append("cancelled")
        if self._proc is not None:
            self._proc.terminate()
            self._proc.join(5)
            if self._proc.is_alive():  # pragma: no cover - terminate ignored
                self._proc.kill()
                self._proc.join(5)
        self._proc = None

    def _drain(self) -> None:
        if self._events is None:
            return
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
            elif what == "done":
                job.status, job.result = "done", payload
            else:
                job.status, job.error = "error", payload
        if self._proc is not None and not self._proc.is_alive():
            for job in self._jobs.values():
                if job.status == "running":
                    job.status, job.error = "error", "the background process ended"
            self._proc = None

    def close(self) -> None:
        with self._lock:
            if self._proc is not None:
                self._proc.terminate()
                self._proc.join(5)
                self._proc = None
