"""Ahead-of-time kernels (maglev_match.core.aot): bitwise the same results as plain jax.jit,
loaded from disk without tracing, keyed so a new parameter value reuses the file, and
robust to corrupt files; plus the light import of the command line."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from maglev_match.core import aot, jax_setup
from maglev_match.core.params import load_preset
from maglev_match.dynamics import collocation, hopf, normal_forms
from maglev_match.maglev import unit, vehicle

P_A = unit.param_vector(load_preset("turnout-soft"))
N = len(unit.STATE_NAMES)


@pytest.fixture
def aot_cache(tmp_path, monkeypatch):
    """A fresh folder for the exported kernels, the mechanism switched on, counters reset."""
    monkeypatch.setattr(jax_setup, "CACHE_DIR", tmp_path)
    monkeypatch.delenv("MAGLEV_MATCH_AOT", raising=False)
    aot.STATS.reset()
    yield tmp_path / "aot"
    aot.STATS.reset()


def _leaves(out):
    return [np.asarray(a) for a in jax.tree_util.tree_leaves(out)]


def _assert_bitwise(a, b):
    la, lb = _leaves(a), _leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb, strict=True):
        assert x.dtype == y.dtype and x.shape == y.shape
        assert x.tobytes() == y.tobytes(), np.max(np.abs(x - y))


def _fresh(fn, *static, name=None):
    """A new Kernel for the same (fn, static, name): what a new process builds."""
    k = aot.cached_kernel(fn, *static, name=name)
    assert isinstance(k, aot.Kernel)
    return k


def _kernels_and_args():
    """(label, kernel function, static ingredients, name, arguments) of three kernels of
    different kinds: the Hopf defining system G, a vmapped multilinear form of order 3 and
    the collocation kernel (NCOL 4, 8 intervals)."""
    rng = np.random.default_rng(0)
    x = rng.normal(scale=1e-3, size=N)
    G = hopf.hopf_defining_kernels(unit.unit_rhs, (15,))[0].fn
    z = np.concatenate([x, rng.normal(size=2 * N), [120.0, P_A[15]]])
    form3 = normal_forms.real_forms(unit.unit_rhs)[3].kernel.fn
    us = [rng.normal(size=(5, N)) for _ in range(3)]
    kern = collocation.collocation_kernel(unit.unit_rhs, 4).fn
    Ui = rng.normal(scale=1e-3, size=(8, 5, N))
    e = np.zeros(P_A.size)
    e[15] = 1.0
    return [
        ("G", G, (unit.unit_rhs, (15,)), "hopf.G", (z, P_A, rng.normal(size=N))),
        ("form3", form3, (unit.unit_rhs, 3), "normal_forms.form", (x, P_A, *us)),
        ("collocation", kern, (unit.unit_rhs, 4), None,
         (Ui, np.full(8, 1 / 8), 0.05, P_A, e)),
    ]


@pytest.mark.parametrize("case", [0, 1, 2], ids=["G", "form3", "collocation"])
def test_exported_and_loaded_kernels_are_bitwise_plain_jit(aot_cache, case):
    label, fn, static, name, args = _kernels_and_args()[case]
    plain = jax.jit(fn)(*args)
    first = _fresh(fn, *static, name=name)
    _assert_bitwise(first(*args), plain)
    assert aot.STATS.exported == 1 and aot.STATS.loaded == 0
    files = list(aot_cache.glob("*.jaxexport"))
    assert len(files) == 1
    second = _fresh(fn, *static, name=name)  # as in a new process: read, not traced
    _assert_bitwise(second(*args), plain)
    assert aot.STATS.loaded == 1 and aot.STATS.exported == 1


def test_compiled_code_is_released_near_the_mapping_limit(aot_cache, monkeypatch):
    """Past its share of vm.max_map_count a process drops the compiled kernels it holds
    (every Kernel's loaded signatures and JAX's caches); the kernels then reload from disk
    with bitwise the same results."""
    cases = _kernels_and_args()
    kernels = [_fresh(fn, *static, name=name) for _, fn, static, name, _ in cases]
    before = [k(*args) for k, (*_, args) in zip(kernels, cases, strict=True)]
    assert all(k._calls for k in kernels) and aot.STATS.released == 0
    monkeypatch.setattr(aot, "MAP_SHARE", 0.0)  # any process is "near the limit"
    monkeypatch.setattr(aot, "MAP_CHECK_EVERY", 1)
    if aot._map_limit() == 0:
        pytest.skip("no vm.max_map_count here (not Linux)")
    form2 = normal_forms.real_forms(unit.unit_rhs)[2].kernel.fn
    kf = _fresh(form2, unit.unit_rhs, 2, name="normal_forms.form")
    kf(np.zeros(N), P_A, np.ones((3, N)), np.ones((3, N)))  # a new signature: the check
    assert aot.STATS.released == 1
    assert not any(k._calls for k in kernels)
    monkeypatch.setattr(aot, "MAP_SHARE", 1.0)
    loaded = aot.STATS.loaded
    for k, (*_, args), ref in zip(kernels, cases, before, strict=True):
        _assert_bitwise(k(*args), ref)
    assert aot.STATS.loaded == loaded + len(kernels)  # read from disk, not traced again


def test_new_parameter_value_reuses_the_exported_kernel(aot_cache):
    _, fn, static, name, (z, p, c) = _kernels_and_args()[0]
    k = _fresh(fn, *static, name=name)
    k(z, p, c)
    q = p.copy()
    q[15] *= 1.3  # omega1
    q[16] *= 0.7  # sigma
    k2 = _fresh(fn, *static, name=name)
    _assert_bitwise(k2(z, q, c), jax.jit(fn)(z, q, c))
    assert aot.STATS.exported == 1 and aot.STATS.loaded == 1
    assert len(list(aot_cache.glob("*.jaxexport"))) == 1
    # a new shape is a new signature: a second file
    form2 = normal_forms.real_forms(unit.unit_rhs)[2].kernel.fn
    kf = _fresh(form2, unit.unit_rhs, 2, name="normal_forms.form")
    x = np.zeros(N)
    kf(x, p, np.ones((3, N)), np.ones((3, N)))
    kf(x, q, np.ones((4, N)), np.ones((4, N)))
    assert len(list(aot_cache.glob("normal_forms.form-*.jaxexport"))) == 2


@pytest.mark.parametrize("garbage", [b"", b"not an exported kernel", None])
def test_corrupt_or_stale_files_are_replaced_never_an_error(aot_cache, garbage):
    _, fn, static, name, args = _kernels_and_args()[0]
    _fresh(fn, *static, name=name)(*args)
    (path,) = aot_cache.glob("*.jaxexport")
    if garbage is None:  # a valid file of another kernel under this name: stale
        other = _kernels_and_args()[1]
        k = _fresh(other[1], *other[2], name="other")
        k(*other[4])
        (other_path,) = [f for f in aot_cache.glob("other-*.jaxexport")]
        path.write_bytes(other_path.read_bytes())
    else:
        path.write_bytes(garbage)
    aot.STATS.reset()
    k = _fresh(fn, *static, name=name)
    _assert_bitwise(k(*args), jax.jit(fn)(*args))
    assert aot.STATS.rejected == 1 and aot.STATS.exported == 1
    aot.STATS.reset()
    _fresh(fn, *static, name=name)(*args)  # rewritten: readable again
    assert aot.STATS.loaded == 1 and aot.STATS.rejected == 0


def test_identity_of_static_ingredients():
    ident = aot.identity
    assert ident(unit.unit_rhs) == ident(unit.unit_rhs)
    assert ident(unit.unit_rhs) != ident(unit.unit_rhs_limited)
    # closures: the captured values are part of the identity
    assert ident(vehicle.vehicle_rhs(3, False)) is not None
    assert ident(vehicle.vehicle_rhs(3, False)) != ident(vehicle.vehicle_rhs(2, False))
    assert ident(vehicle.vehicle_rhs(3, False)) != ident(vehicle.vehicle_rhs(3, True))
    assert ident((1, 2.0, "a")) != ident((1, 2.0, "b"))
    assert ident(np.arange(3.0)) != ident(np.arange(3.0) + np.array([0, 0, 1e-9]))
    # no stable identity: a function of another module (a user's model file), an object,
    # a closure over one
    assert ident(np.sin) is None
    assert ident(lambda x, p: x) is None  # defined in this test module, not the package
    assert ident(object()) is None
    obj = object()

    def factory():
        def rhs(x, p):
            return obj

        return rhs

    assert ident(factory()) is None


def test_user_model_and_switched_off_cache_use_plain_jit(aot_cache, monkeypatch, tmp_path):
    def rhs(x, p):  # this test module is not the package: no identity
        return -x * p[0]

    k = aot.cached_kernel(rhs, rhs, name="user")
    assert not isinstance(k, aot.Kernel)
    assert np.allclose(k(jnp.ones(2), jnp.array([2.0])), -2.0)
    monkeypatch.setenv("MAGLEV_MATCH_AOT", "0")
    assert not isinstance(aot.cached_kernel(unit.unit_rhs, unit.unit_rhs), aot.Kernel)
    monkeypatch.delenv("MAGLEV_MATCH_AOT")
    monkeypatch.setattr(jax_setup, "CACHE_DIR", None)
    assert aot.aot_dir() is None
    assert not isinstance(aot.cached_kernel(unit.unit_rhs, unit.unit_rhs), aot.Kernel)
    assert not aot_cache.exists()


def test_kernel_inside_another_trace_is_inlined(aot_cache):
    k = _fresh(unit.unit_rhs, unit.unit_rhs, name="f")
    x = np.full(N, 1e-4)
    outer = jax.jit(lambda y, p: 2.0 * k(y, p))
    _assert_bitwise(outer(x, P_A), jax.jit(lambda y, p: 2.0 * unit.unit_rhs(y, p))(x, P_A))
    assert aot.STATS.exported == 0  # the traced call never exports
    jac = jax.jacfwd(k)(jnp.asarray(x), jnp.asarray(P_A))
    assert jac.shape == (N, N)


def test_a_new_process_loads_kernels_without_tracing(tmp_path):
    """Two processes with the same cache: the second reads every kernel it exported, traces
    none of the package's kernels, and gets bitwise the same l1 and Jacobian."""
    script = textwrap.dedent("""
        import logging, sys
        import numpy as np
        from maglev_match.core import aot
        from maglev_match.maglev.unit import unit_system
        from maglev_match.core.params import load_preset
        from maglev_match.dynamics.hopf import locate_hopf_points
        import jax
        jax.config.update("jax_log_compiles", True)
        traced = []
        class H(logging.Handler):
            def emit(self, rec):
                msg = rec.getMessage()
                if msg.startswith("Finished tracing"):
                    traced.append(msg.split()[2])
        for name in ("jax._src.dispatch", "jax._src.interpreters.pxla", "jax"):
            logging.getLogger(name).addHandler(H()); logging.getLogger(name).setLevel(10)
        s = unit_system(load_preset("turnout-soft"))
        pts = locate_hopf_points(s, "omega1", 60.0, 200.0, n_scan=40).points
        J = s.jacobian(np.zeros(s.dim))
        print(repr([pt.l1 for pt in pts]), J.tobytes().hex()[:4000])
        print(aot.STATS.exported, aot.STATS.loaded, sorted(set(traced)))
    """)
    env = {**os.environ, "MAGLEV_MATCH_CACHE": str(tmp_path), "MAGLEV_MATCH_AOT": "1"}
    runs = [subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                           text=True, check=True).stdout.splitlines() for _ in range(2)]
    assert runs[0][0] == runs[1][0]  # l1 values and Jacobian: bitwise the same
    exported0, loaded0, _ = runs[0][1].split(" ", 2)
    exported1, loaded1, traced1 = runs[1][1].split(" ", 2)
    assert int(exported0) > 0 and int(loaded0) == 0
    assert int(exported1) == 0 and int(loaded1) == int(exported0)
    package_kernels = ("G", "DG", "form", "kernel", "dJv", "unit_rhs", "jacfwd")
    assert not any(k in traced1 for k in package_kernels), traced1


def test_cli_import_does_not_load_heavy_optional_modules():
    code = ("import sys, maglev_match.cli\n"
            "print([m for m in ('dask', 'distributed', 'xarray', 'matplotlib', 'diffrax', "
            "'pandas', 'scipy.optimize') if m in sys.modules])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]", f"import maglev_match.cli loaded: {out}"


def test_prune_removes_only_old_files_of_other_environments(aot_cache):
    _, fn, static, name, args = _kernels_and_args()[0]
    _fresh(fn, *static, name=name)(*args)
    (current,) = aot_cache.glob("*.jaxexport")
    other_old = aot_cache / "hopf.G-000000000000-0123.jaxexport"
    other_new = aot_cache / "hopf.G-111111111111-0123.jaxexport"
    for f in (other_old, other_new):
        f.write_bytes(b"x")
    old = 30 * 86400.0
    os.utime(other_old, (os.path.getmtime(other_old) - old,) * 2)
    os.utime(current, (os.path.getmtime(current) - old,) * 2)  # old, but this environment
    assert aot.prune(aot_cache) == 1
    assert sorted(f.name for f in aot_cache.glob("*.jaxexport")) == sorted(
        [current.name, other_new.name])
