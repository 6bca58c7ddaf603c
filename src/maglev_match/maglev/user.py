"""User models: an ODE system x' = f(x, p) defined in a Python file.

The file defines, at module level::

    STATES = ["x", "y", "z"]                          # names of the states (list of str)
    PARAMS = {"sigma": 10.0, "rho": 28.0, ...}        # name -> default value (SI units)
    def rhs(x, p): ...                                # jax.numpy; x 1-D array, p mapping
    X0 = [...]                                        # optional: equilibrium guess
    SCALES = [...]                                    # optional: typical size of each state
    OBSERVABLES = {"name": lambda x, p: ...}          # optional: read-outs g(x, p)

A delay model also defines ``DELAYS``, a tuple of PARAMS names, each a delay (seconds, or
the model's time unit; default values >= 0), and writes ``rhs(x, xd, p)`` with ``xd[k]`` the
state at t - p[DELAYS[k]] (``xd`` has shape (len(DELAYS), len(STATES))). A file without
DELAYS keeps ``rhs(x, p)``. The delay model's system is the discretisation of
:mod:`maglev_match.dynamics.delay` (the delay-free ODE rhs(x, [x, ..., x], p) when every
delay is 0), so every analysis accepts it; its past holds the whole state (m = n).

``rhs`` must be written with ``jax.numpy`` so that it can be traced and differentiated
exactly (no ``numpy``/``math`` on the state, no ``float()``, no Python ``if`` on a value
that depends on x or p: use ``jnp.where``). :func:`load_model` checks all of this once, by
evaluating and tracing the file's functions at X0 and the defaults, and turns every problem
into a :class:`ModelFileError` whose one-line message names the file and the problem.

A model file is trusted code: it runs with the rights of the user. What can be caught is
caught, so that a careless file ends the command with one clear line instead of silence:
the file runs under a guard (:func:`_guarded`) while it is loaded and every time its
functions are traced — ``sys.exit`` and ``os._exit`` become a :class:`ModelFileError`,
anything it prints goes to stderr (stdout stays clean for ``--json``), and the load is given
``LOAD_TIMEOUT`` seconds (``MAGLEV_MATCH_MODEL_TIMEOUT``) before it is stopped as endless.
The right-hand side must be real (complex values are refused, not cut to their real part),
finite with a finite Jacobian at X0 and finite on a small neighbourhood of X0
(:func:`_check_neighbourhood`), so that no analysis draws a verdict from a field that is
undefined around the point it studies; :meth:`UserModel.numerical_problem` applies the same
test to other parameter values (``--set rho=1e308`` overflows, a numerical failure).

The result is a :class:`UserModel`; ``UserModel.system(values)`` gives the model-agnostic
:class:`~maglev_match.dynamics.system.System` every analysis works on.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import math
import os
import signal
import stat
import sys
import threading
import traceback
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from numbers import Real
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.errors import ModelFileError
from maglev_match.dynamics.system import System

__all__ = ["ModelFileError", "UserModel", "is_model_file", "load_model", "LOAD_TIMEOUT"]

#: Seconds a model file may take to load (run the file, trace and compile its functions
#: once); ``MAGLEV_MATCH_MODEL_TIMEOUT`` overrides it. An endless loop at import or in
#: ``rhs`` ends with a message instead of a hang.
LOAD_TIMEOUT = 60.0
#: Relative size (in units of SCALES) of the neighbourhood of X0 on which the right-hand
#: side must be finite: small enough that a genuine singularity of a model is not met, large
#: enough that a field defined only at X0 itself (NaN elsewhere) is caught.
NEIGHBOURHOOD = 1e-6

_TRACE_ERRORS = (
    jax.errors.ConcretizationTypeError,
    jax.errors.TracerArrayConversionError,
    jax.errors.TracerBoolConversionError,
    jax.errors.TracerIntegerConversionError,
)


def is_model_file(model: str) -> bool:
    """True when a ``--model`` value names a Python file rather than a built-in model."""
    return str(model).endswith(".py")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def _line_in(path: Path, exc: BaseException) -> str:
    """' (line N)' of the innermost frame of ``exc`` inside the model file, if any."""
    line = None
    for fr in traceback.extract_tb(exc.__traceback__):
        if Path(fr.filename).resolve() == path.resolve():
            line = fr.lineno
    return f" (line {line})" if line is not None else ""


# ---------------------------------------------------------------------------------------
# the guard around the user's code
# ---------------------------------------------------------------------------------------
class _ExitRequested(BaseException):
    """Raised by the stand-in of ``os._exit`` while the user's code runs."""

    def __init__(self, code: Any):
        self.code = code
        super().__init__(code)


#: seconds between repeated alarms once a user model's time limit has passed
ALARM_REPEAT = 0.25


class _LoadTimeout(BaseException):
    """The load took longer than its timeout (raised by the SIGALRM handler)."""


def _no_os_exit(code: Any = 0) -> None:
    raise _ExitRequested(code)


def _load_timeout() -> float:
    text = os.environ.get("MAGLEV_MATCH_MODEL_TIMEOUT", "").strip()
    try:
        value = float(text) if text else LOAD_TIMEOUT
    except ValueError:
        value = LOAD_TIMEOUT
    return value if math.isfinite(value) and value > 0 else LOAD_TIMEOUT


@contextlib.contextmanager
def _guarded(path: Path, what: str, timeout: float | None = None) -> Iterator[None]:
    """Run the user's code (``what``: "loading", "rhs", ...) so that it cannot end the
    process or pollute stdout: ``sys.exit`` (SystemExit) and ``os._exit`` become a
    :class:`ModelFileError`, ``print`` goes to stderr, and with ``timeout`` (seconds; main
    thread only, where SIGALRM can be handled) an endless loop is stopped."""
    saved_exit = os._exit
    os._exit = _no_os_exit  # type: ignore[assignment]
    alarm = (timeout is not None and hasattr(signal, "SIGALRM")
             and threading.current_thread() is threading.main_thread())
    old_handler: Any = None
    old_timer = (0.0, 0.0)
    armed = [alarm]
    if alarm:
        def on_alarm(signum, frame):
            if armed[0]:
                raise _LoadTimeout()

        old_handler = signal.signal(signal.SIGALRM, on_alarm)
        saved_hook = sys.unraisablehook

        def quiet_timeout(unraisable):  # (the ignored copy is raised again: see below)
            if not isinstance(unraisable.exc_value, _LoadTimeout):
                saved_hook(unraisable)

        sys.unraisablehook = quiet_timeout
        # the timer repeats after it first fires: an exception raised where Python ignores
        # it (a garbage-collection callback, e.g. JAX's, running inside the user's loop)
        # is raised again a moment later, in the loop itself
        old_timer = signal.setitimer(signal.ITIMER_REAL, float(timeout), ALARM_REPEAT)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    except SystemExit as exc:
        raise ModelFileError(path, f"{what} called sys.exit({exc.code!r}){_line_in(path, exc)};"
                             " a model file must not end the program") from None
    except _ExitRequested as exc:
        raise ModelFileError(path, f"{what} called os._exit({exc.code!r}){_line_in(path, exc)};"
                             " a model file must not end the program") from None
    except _LoadTimeout as exc:
        armed[0] = False
        if not alarm:  # an outer guard's timer: its guard reports it
            raise
        raise ModelFileError(path, f"{what} did not finish within {timeout:g} s"
                             f"{_line_in(path, exc)} (an endless loop?); the limit is "
                             "MAGLEV_MATCH_MODEL_TIMEOUT seconds") from None
    finally:
        armed[0] = False
        os._exit = saved_exit  # type: ignore[assignment]
        if alarm:
            signal.setitimer(signal.ITIMER_REAL, *old_timer)
            signal.signal(signal.SIGALRM, old_handler)
            sys.unraisablehook = saved_hook


@dataclass(frozen=True, eq=False)
class UserModel:
    """A model loaded from a file.

    name : the file's stem (used in output names).
    path : the file.
    states : state names.
    params : default parameter values, name -> value.
    x0 : equilibrium guess (zeros if the file gives none).
    scales : typical magnitude of each state (ones if the file gives none).
    observables : name -> g(x, p) with p a mapping (as in the file).
    rhs : the file's ``rhs(x, p)``, or ``rhs(x, xd, p)`` for a delay model (p a mapping).
    delays : the names in DELAYS (empty for an ODE model).
    """

    name: str
    path: Path
    states: tuple[str, ...]
    params: Mapping[str, float]
    x0: np.ndarray
    scales: np.ndarray
    observables: Mapping[str, Callable[..., Any]]
    rhs: Callable[..., Any]
    _vector_rhs: Callable[..., Any] = field(repr=False, default=None)  # type: ignore[assignment]
    _vector_obs: Mapping[str, Callable[..., Any]] = field(repr=False, default_factory=dict)
    delays: tuple[str, ...] = ()

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(self.params)

    @property
    def defaults(self) -> dict[str, float]:
        return dict(self.params)

    def values_with(self, overrides: Mapping[str, float] | None = None) -> dict[str, float]:
        """The defaults with some values replaced; an unknown name is a ValueError that lists
        the valid ones."""
        vals = dict(self.params)
        for k, v in (overrides or {}).items():
            if k not in vals:
                raise ValueError(f"model '{self.name}' has no parameter '{k}'; "
                                 f"valid names: {', '.join(self.params)}")
            vals[k] = float(v)
        return vals

    def numerical_problem(self, values: Mapping[str, float] | None = None) -> str | None:
        """Why the right-hand side cannot be analysed at these parameter values (it or its
        Jacobian is not finite at X0, e.g. an overflow from ``--set rho=1e308``), or None.
        A numerical failure to report, never a stability verdict to print."""
        vals = self.values_with(values)
        p = jnp.asarray([vals[n] for n in self.param_names], dtype=jnp.float64)
        x = jnp.asarray(self.x0)
        with np.errstate(all="ignore"):
            f = np.asarray(_finite_kernel(self._ode_rhs)(x, p))
            J = np.asarray(jax.jacfwd(_finite_kernel(self._ode_rhs))(x, p))
        changed = ", ".join(f"{k} = {v:g}" for k, v in (values or {}).items())
        at = f" with {changed}" if changed else ""
        if not np.all(np.isfinite(f)):
            return (f"the right-hand side is not finite at X0{at} ({_short(f)}): an "
                    "overflow or a value outside the model's domain")
        if not np.all(np.isfinite(J)):
            return (f"the Jacobian of the right-hand side is not finite at X0{at}: an "
                    "overflow or a value outside the model's domain")
        return None

    @property
    def _ode_rhs(self) -> Callable[..., Any]:
        """The right-hand side as ``f(x, p)``; for a delay model with a constant past
        (every delayed state equal to x: the equilibria and the delay-free model)."""
        if not self.delays:
            return self._vector_rhs
        return _constant_past(self._vector_rhs, len(self.delays))

    def system(self, values: Mapping[str, float] | None = None, *,
               tau_max: float | None = None) -> System:
        """The :class:`System` at the defaults with ``values`` applied. Every System of one
        UserModel shares the same right-hand side function, so it is compiled once.

        A delay model gives its discretised system (:func:`delay_model_system`) when a
        delay is positive or ``tau_max`` asks for a delay axis; with every delay 0 and no
        axis, the delay-free ODE."""
        vals = self.values_with(values)
        if self.delays:
            return delay_model_system(self, vals, tau_max=tau_max)
        return System(
            rhs=self._vector_rhs,
            p=np.array([vals[n] for n in self.param_names], float),
            param_names=self.param_names,
            state_names=self.states,
            x_guess=self.x0,
            state_scale=self.scales,
            observables=dict(self._vector_obs),
            name=self.name,
        )


@functools.cache
def _finite_kernel(g: Callable[..., Any]) -> Callable[..., Any]:
    return jax.jit(g)


def _short(values: np.ndarray) -> str:
    text = np.array2string(np.asarray(values), precision=4, separator=", ", threshold=8)
    return " ".join(text.split())


def _vectorised(fn: Callable[..., Any], names: tuple[str, ...], path: Path | None = None,
                what: str = "rhs") -> Callable[..., Any]:
    """``fn(x, mapping)`` as ``g(x, p_vector)`` (the form System expects): the mapping is
    built from the vector inside the trace, so derivatives in p stay exact. The user's
    function runs under :func:`_guarded` (it runs only while JAX traces it), and a complex
    result is refused: the vector field of a real ODE is real, and casting would keep only
    the real part without a word."""

    def g(x, p):
        if path is None:
            out = fn(x, {n: p[i] for i, n in enumerate(names)})
        else:
            with _guarded(path, what):
                out = fn(x, {n: p[i] for i, n in enumerate(names)})
        if jnp.iscomplexobj(out):
            raise ModelFileError(path or "?", f"{what} returns complex numbers "
                                 f"({jnp.result_type(out)}); the vector field must be real "
                                 "(complex arithmetic inside is fine: return jnp.real(...) "
                                 "of a quantity that is real)")
        return jnp.asarray(out, dtype=jnp.float64)

    g.__name__ = getattr(fn, "__name__", "user_function")
    return g


def _real_vector(path: Path, name: str, value: Any, n: int) -> np.ndarray:
    if isinstance(value, str | bytes | Mapping):
        raise ModelFileError(path, f"{name} must be a list of {n} numbers, got "
                             f"{type(value).__name__}")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelFileError(path, f"{name} must be a list of {n} numbers, got "
                             f"{type(value).__name__}") from None
    if arr.ndim > 1:
        raise ModelFileError(path, f"{name} must be a flat list of {n} numbers (one per "
                             f"state in STATES), got a nested list of shape {arr.shape}")
    if arr.shape != (n,):
        raise ModelFileError(path, f"{name} has {arr.size if arr.ndim else 'a scalar'} "
                             f"entries, expected {n} (one per state in STATES)")
    if not np.all(np.isfinite(arr)):
        raise ModelFileError(path, f"{name} has non-finite entries: {arr.tolist()}")
    return arr


def _import(path: Path, timeout: float | None = None):
    try:
        source = path.read_bytes()
    except OSError as exc:
        raise ModelFileError(path, f"cannot be read ({_first_line(exc)})") from None
    if b"\x00" in source:  # Python refuses these before parsing, without a line number
        line = source[: source.index(b"\x00")].count(b"\n") + 1
        raise ModelFileError(path, f"contains a NUL byte at line {line}: not a Python "
                             "source file (saved in another encoding, or binary?)")
    try:
        # decoded as Python's import decodes a source file: a UTF-8 byte-order mark and a
        # coding declaration are honoured, any other byte that is not UTF-8 is an error
        text = importlib.util.decode_source(source)
    except (UnicodeDecodeError, SyntaxError, LookupError) as exc:
        try:
            source.decode("utf-8-sig")
        except UnicodeDecodeError as bad:  # a byte that is not UTF-8, no declaration
            line = source[: bad.start].count(b"\n") + 1
            raise ModelFileError(path, f"is not UTF-8 text (byte 0x{source[bad.start]:02x} "
                                 f"at line {line}): save it as UTF-8 or declare its encoding "
                                 "on the first line (# -*- coding: latin-1 -*-)") from None
        raise ModelFileError(path, f"cannot be decoded: {_first_line(exc)}") from None
    try:
        code = compile(text, str(path), "exec", dont_inherit=True)
    except SyntaxError as exc:
        where = f" at line {exc.lineno}" if exc.lineno is not None else ""
        raise ModelFileError(path, f"syntax error{where}: {exc.msg}") from None
    except ValueError as exc:  # e.g. an unknown coding declaration
        raise ModelFileError(path, f"cannot be compiled: {_first_line(exc)}") from None
    modname = f"maglev_match_user_model_{abs(hash(str(path.resolve())))}"
    spec = importlib.util.spec_from_loader(modname, loader=None, origin=str(path))
    module = importlib.util.module_from_spec(spec)
    module.__file__ = str(path)
    sys.modules[modname] = module  # dataclasses and pickling look their module up
    try:
        with _guarded(path, "the file, while loading,", timeout):
            exec(code, module.__dict__)  # noqa: S102  (running the user's model file is the point)
    except ModelFileError:
        raise
    except Exception as exc:  # anything the file raises while loading
        raise ModelFileError(path, f"error while loading{_line_in(path, exc)}: "
                             f"{_first_line(exc)}") from None
    return module


def _check_traceable(path: Path, what: str, fn: Callable, x: np.ndarray, p: np.ndarray,
                     timeout: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate ``fn(x, p)`` under jit and its x-Jacobian under jacfwd; return both."""
    hint = ("write it with jax.numpy (jnp.sin, jnp.where ...), not numpy/math, float() or a "
            "Python `if` on values that depend on x or p")
    try:
        with _guarded(path, what, timeout), np.errstate(all="ignore"):
            val = jax.jit(fn)(jnp.asarray(x), jnp.asarray(p))
            jac = jax.jit(jax.jacfwd(fn))(jnp.asarray(x), jnp.asarray(p))
    except ModelFileError:
        raise
    except _TRACE_ERRORS as exc:
        raise ModelFileError(path, f"{what} is not JAX-traceable{_line_in(path, exc)}: "
                             f"{type(exc).__name__}; {hint}") from None
    except Exception as exc:
        raise ModelFileError(path, f"{what} failed at X0 and the default parameters"
                             f"{_line_in(path, exc)}: {_first_line(exc)}") from None
    return np.asarray(val), np.asarray(jac)


def _check_neighbourhood(path: Path, fn: Callable, x0: np.ndarray, p: np.ndarray,
                         scales: np.ndarray, names: tuple[str, ...]) -> None:
    """The right-hand side must be finite on a small neighbourhood of X0: at X0 +- h e_k
    for every state k and at eight points in random directions, h = NEIGHBOURHOOD SCALES.
    A field that is finite only at X0 (NaN elsewhere) would otherwise get an exact but
    meaningless Jacobian there, and with it a stability verdict."""
    n = x0.size
    h = NEIGHBOURHOOD * scales
    dirs = np.vstack([np.eye(n), -np.eye(n),
                      np.random.default_rng(0).uniform(-1.0, 1.0, (8, n))])
    pts = x0[None, :] + dirs * h[None, :]
    with np.errstate(all="ignore"):
        vals = np.asarray(jax.jit(jax.vmap(fn, in_axes=(0, None)))(jnp.asarray(pts),
                                                                    jnp.asarray(p)))
    bad = ~np.all(np.isfinite(vals), axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        where = (f"X0 {'+' if k < n else '-'} {NEIGHBOURHOOD:g} SCALES along "
                 f"'{names[k % n]}'" if k < 2 * n else
                 f"a point {NEIGHBOURHOOD:g} SCALES from X0")
        raise ModelFileError(path, f"rhs is not finite near X0 ({int(bad.sum())} of "
                             f"{len(pts)} points within {NEIGHBOURHOOD:g} SCALES): at {where} "
                             f"it is {_short(vals[k])}; the vector field must be defined "
                             "around the equilibrium guess")


def load_model(path: str | Path, timeout: float | None = None) -> UserModel:
    """Load and check a user model file (see the module docstring for the contract).

    Parameters
    ----------
    path : the ``.py`` file.
    timeout : seconds the load may take (default ``MAGLEV_MATCH_MODEL_TIMEOUT`` or
        :data:`LOAD_TIMEOUT`); only enforced in the main thread.

    Returns
    -------
    UserModel.

    Raises
    ------
    ModelFileError : the file is missing, a directory or another non-regular file, not
        Python, fails to load (or exits, or runs past the timeout), misses STATES/PARAMS/rhs,
        has values of the wrong type or length, an rhs that is not JAX-traceable, complex,
        of the wrong shape, not finite (or with a non-finite Jacobian) at X0 or not finite
        near X0, or non-positive SCALES.
    """
    path = Path(path)
    if path.suffix != ".py":
        raise ModelFileError(path, "a model file must be a Python file ending in .py")
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise ModelFileError(path, "no such file" + (" (a link to a missing file)"
                                                     if path.is_symlink() else "")) from None
    except OSError as exc:
        raise ModelFileError(path, f"cannot be read ({_first_line(exc)})") from None
    if stat.S_ISDIR(mode):
        raise ModelFileError(path, "is a directory, not a file")
    if not stat.S_ISREG(mode):
        kind = ("a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
                "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else
                "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
        raise ModelFileError(path, f"is {kind}, not a regular file; give the Python file "
                             "itself")
    timeout = _load_timeout() if timeout is None else float(timeout)
    mod = _import(path, timeout)
    missing = [k for k in ("STATES", "PARAMS", "rhs") if not hasattr(mod, k)]
    if missing:
        raise ModelFileError(path, f"missing {', '.join(missing)} (a model file defines "
                             "STATES, PARAMS and rhs(x, p))")
    states = mod.STATES
    if (not isinstance(states, list | tuple) or not states
            or not all(isinstance(s, str) and s for s in states)):
        raise ModelFileError(path, f"STATES must be a non-empty list of names (strings), got "
                             f"{states!r}"[:200])
    if len(set(states)) != len(states):
        raise ModelFileError(path, f"STATES has repeated names: {list(states)}")
    params = mod.PARAMS
    if not isinstance(params, Mapping):
        raise ModelFileError(path, f"PARAMS must be a dict name -> default value, got "
                             f"{type(params).__name__}")
    clean: dict[str, float] = {}
    for k, v in params.items():
        if not isinstance(k, str) or not k or "=" in k:
            raise ModelFileError(path, f"PARAMS key {k!r} must be a non-empty name without '='")
        if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(float(v)):
            raise ModelFileError(path, f"PARAMS['{k}'] = {v!r} must be a finite number")
        clean[k] = float(v)
    if not callable(mod.rhs):
        raise ModelFileError(path, f"rhs must be a function rhs(x, p), got "
                             f"{type(mod.rhs).__name__}")
    n = len(states)
    x0 = (_real_vector(path, "X0", mod.X0, n) if getattr(mod, "X0", None) is not None
          else np.zeros(n))
    scales = (_real_vector(path, "SCALES", mod.SCALES, n)
              if getattr(mod, "SCALES", None) is not None else np.ones(n))
    if np.any(scales <= 0.0):
        raise ModelFileError(path, f"SCALES must be positive (typical size of each state), "
                             f"got {scales.tolist()}")
    obs_in = getattr(mod, "OBSERVABLES", None) or {}
    if not isinstance(obs_in, Mapping) or not all(
            isinstance(k, str) and callable(f) for k, f in obs_in.items()):
        raise ModelFileError(path, "OBSERVABLES must be a dict name -> function g(x, p)")
    names = tuple(clean)
    p0 = np.array([clean[k] for k in names], float)
    delays = check_delays(path, mod, clean)
    if delays:
        vrhs = _vectorised_delayed(mod.rhs, names, path)
        f0, J0 = _check_delayed_rhs(path, vrhs, x0, p0, len(delays), timeout)
        ode_rhs = _constant_past(vrhs, len(delays))
    else:
        vrhs = _vectorised(mod.rhs, names, path, "rhs")
        f0, J0 = _check_traceable(path, "rhs", vrhs, x0, p0, timeout)
        ode_rhs = vrhs
    if f0.shape != (n,):
        raise ModelFileError(path, f"rhs returns shape {f0.shape}, expected ({n},) "
                             "(one derivative per state in STATES)")
    if not np.all(np.isfinite(f0)):
        raise ModelFileError(path, f"rhs is not finite at X0 = {x0.tolist()}: {f0.tolist()}")
    if not np.all(np.isfinite(J0)):
        raise ModelFileError(path, f"the Jacobian of rhs is not finite at X0 = {x0.tolist()} "
                             "(e.g. sqrt or a power at the edge of its domain); move X0 "
                             "inside the domain")
    _check_neighbourhood(path, ode_rhs, x0, p0, scales, tuple(states))
    vobs = {}
    for k, g in obs_in.items():
        vg = _vectorised(g, names, path, f"OBSERVABLES['{k}']")
        val, _ = _check_traceable(path, f"OBSERVABLES['{k}']", vg, x0, p0, timeout)
        if val.ndim > 1:
            raise ModelFileError(path, f"OBSERVABLES['{k}'] returns shape {val.shape}; "
                                 "expected a scalar or a 1-D array")
        vobs[k] = vg
    return UserModel(name=path.stem, path=path, states=tuple(states), params=clean, x0=x0,
                     scales=scales, observables=dict(obs_in), rhs=mod.rhs, _vector_rhs=vrhs,
                     _vector_obs=vobs, delays=delays)


# ---------------------------------------------------------------------------------------
# delay models: the DELAYS contract and their systems
# ---------------------------------------------------------------------------------------
def _positional_count(fn: Callable) -> int | None:
    """Number of positional parameters of ``fn`` (None when it cannot be told, e.g. *args)."""
    import inspect

    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return None
    kinds = [prm.kind for prm in sig.parameters.values()]
    if inspect.Parameter.VAR_POSITIONAL in kinds:
        return None
    return sum(k in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
               for k in kinds)


def check_delays(path: Path, mod: Any, params: Mapping[str, float]) -> tuple[str, ...]:
    """The DELAYS of a model file, checked: a tuple (or list) of distinct PARAMS names whose
    default values are >= 0, with an ``rhs(x, xd, p)`` of three arguments; a file without
    DELAYS must have ``rhs(x, p)``. Returns () for an ODE model."""
    delays = getattr(mod, "DELAYS", None)
    count = _positional_count(mod.rhs)
    if delays is None:
        if count == 3:
            raise ModelFileError(path, "rhs takes three arguments (x, xd, p), a delay model's "
                                 "form, but the file defines no DELAYS; add DELAYS = "
                                 "(\"tau\",) naming the delay parameters, or write rhs(x, p)")
        return ()
    if isinstance(delays, str) or not isinstance(delays, list | tuple) or not delays:
        raise ModelFileError(path, f"DELAYS = {delays!r} must be a non-empty tuple of PARAMS "
                             "names, e.g. DELAYS = (\"tau\",)"[:300])
    for d in delays:
        if not isinstance(d, str) or d not in params:
            raise ModelFileError(path, f"DELAYS entry {d!r} is not a name in PARAMS "
                                 f"({', '.join(params) or 'none'})")
        if not params[d] >= 0:
            raise ModelFileError(path, f"PARAMS['{d}'] = {params[d]!r} is a delay (in DELAYS) "
                                 "and must be >= 0")
    if len(set(delays)) != len(delays):
        raise ModelFileError(path, f"DELAYS has repeated names: {list(delays)}")
    if count is not None and count != 3:
        raise ModelFileError(path, f"a delay model (DELAYS = {tuple(delays)}) defines "
                             f"rhs(x, xd, p) with xd[k] the state at t - DELAYS[k]; its rhs "
                             f"takes {count} argument(s)")
    return tuple(delays)


def _vectorised_delayed(fn: Callable[..., Any], names: tuple[str, ...],
                        path: Path | None = None, what: str = "rhs") -> Callable[..., Any]:
    """``fn(x, xd, mapping)`` as ``g(x, yd, p_vector)`` with ``yd`` the tuple of delayed
    states (one per delay) that :class:`~maglev_match.dynamics.delay.DelayDifferentialSystem`
    passes; ``xd`` is given to the file as a (K, n) array. Guarded and refused when complex
    as :func:`_vectorised`."""

    def g(x, yd, p):
        xd = jnp.stack([jnp.reshape(y, (-1,)) for y in yd])
        if path is None:
            out = fn(x, xd, {n: p[i] for i, n in enumerate(names)})
        else:
            with _guarded(path, what):
                out = fn(x, xd, {n: p[i] for i, n in enumerate(names)})
        if jnp.iscomplexobj(out):
            raise ModelFileError(path or "?", f"{what} returns complex numbers "
                                 f"({jnp.result_type(out)}); the vector field must be real")
        return jnp.asarray(out, dtype=jnp.float64)

    g.__name__ = getattr(fn, "__name__", "user_function")
    g.__wrapped_rhs__ = fn  # the file's own function (see _check_delay_indices)
    g.__param_names__ = names
    return g


def _constant_past(vrhs: Callable, n_delays: int) -> Callable[..., Any]:
    """A delayed right-hand side ``g(x, yd, p)`` with every delayed state equal to x, as
    ``f(x, p)`` (the delay-free model; its equilibria are those of the delay system)."""

    def f(x, p):
        return vrhs(x, tuple(x for _ in range(n_delays)), p)

    f.__name__ = getattr(vrhs, "__name__", "user_function")
    return f


def _check_delayed_rhs(path: Path, vrhs: Callable, x0: np.ndarray, p0: np.ndarray,
                       n_delays: int, timeout: float | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate the delayed ``rhs(x, xd, p)`` at x = X0, xd = (X0, ..., X0) under jit and
    its derivatives in x and xd; return the value (its shape is checked by the caller) and
    the Jacobian of the delay-free model (constant past) at X0."""
    yd = tuple(jnp.asarray(x0) for _ in range(n_delays))

    def both(x, p):
        return vrhs(x, yd, p)

    def delayed(y, p):
        return vrhs(jnp.asarray(x0), tuple(y for _ in range(n_delays)), p)

    val, _ = _check_traceable(path, "rhs(x, xd, p)", both, x0, p0, timeout)
    _check_traceable(path, "rhs(x, xd, p) (in xd)", delayed, x0, p0, timeout)
    _, jac = _check_traceable(path, "rhs(x, xd, p) (constant past)",
                              _constant_past(vrhs, n_delays), x0, p0, timeout)
    _check_delay_indices(path, vrhs, x0, p0, n_delays)
    return val, jac


def _check_delay_indices(path: Path, vrhs: Callable, x0: np.ndarray, p0: np.ndarray,
                         n_delays: int) -> None:
    """``xd[k]`` must name a delay of the file: traced by JAX, an index past the end is
    clamped silently (``xd[1]`` with one delay would read ``xd[0]``). One plain NumPy call
    of ``rhs`` (after the traced checks, so no loop can hang here) shows such an index as
    an IndexError; any other error of a NumPy call is left to the traced checks (a file
    may use JAX-only operations)."""
    fn = getattr(vrhs, "__wrapped_rhs__", None)
    if fn is None:
        return
    names = vrhs.__param_names__
    xd = np.tile(np.asarray(x0, dtype=float), (n_delays, 1))
    try:
        with _guarded(path, "rhs"):
            fn(np.asarray(x0, dtype=float), xd, {n: float(p0[i]) for i, n in enumerate(names)})
    except IndexError as exc:
        rows = "xd[0]" if n_delays == 1 else f"xd[0] .. xd[{n_delays - 1}]"
        raise ModelFileError(path, f"rhs reads past the delayed states ({exc}): xd has one "
                             f"row per entry of DELAYS ({n_delays}), so only {rows} "
                             "exist") from None
    except Exception:  # noqa: BLE001 - the traced checks judge the file
        return


def _identity_signal(x, p):
    return x


def delay_model_system(user: UserModel, values: Mapping[str, float], *,
                       tau_max: float | None = None) -> System:
    """The system of a delay model at ``values`` (all parameters): the discretisation of
    its delay system (:func:`~maglev_match.dynamics.delay.discretise`) when a delay is
    positive or ``tau_max`` is given, else the delay-free ODE. A negative delay or one too
    long for the discretisation is a ParameterError naming it."""
    from maglev_match.core.params import ParameterError
    from maglev_match.dynamics.delay import (
        DelayDifferentialSystem,
        DelayNodesError,
        discretise,
    )

    names = user.param_names
    p = np.array([values[n] for n in names], float)
    for d in user.delays:
        if not values[d] >= 0:
            raise ParameterError(d, values[d], "a delay must be >= 0")
    dde = DelayDifferentialSystem(
        rhs=user._vector_rhs, signals=tuple(_identity_signal for _ in user.delays),
        delays=user.delays, p=p, param_names=names, state_names=user.states,
        x_guess=user.x0, state_scale=user.scales, observables=dict(user._vector_obs),
        name=user.name, signal_names=tuple(user.states for _ in user.delays))
    if tau_max is None and not any(values[d] > 0 for d in user.delays):
        return dde.ode_system()
    try:
        return discretise(dde, tau_max=tau_max)
    except DelayNodesError as exc:
        raise ParameterError(exc.field, exc.value, exc.rule) from None
