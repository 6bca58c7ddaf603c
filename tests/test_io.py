"""Atomic outputs: a file is replaced completely or not at all, also under kill -9."""

import os
import signal
import stat
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from maglev_match.core.io import atomic_open, atomic_write, atomic_write_text


def _leftovers(folder):
    return [p.name for p in folder.iterdir() if ".tmp" in p.name]


def test_atomic_write_replaces_content_and_keeps_suffix(tmp_path):
    target = tmp_path / "data.npz"
    seen = []

    def writer(tmp):
        seen.append(tmp)
        np.savez(tmp, a=np.arange(3))

    atomic_write(target, writer)
    assert seen[0].parent == tmp_path and seen[0].suffix == ".npz" and seen[0] != target
    with np.load(target) as z:
        assert z["a"].tolist() == [0, 1, 2]
    assert _leftovers(tmp_path) == []
    # the usual permissions (0666 minus umask), not mkstemp's 0600
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask


def test_failed_writer_leaves_old_file_and_no_temp(tmp_path):
    target = tmp_path / "out.csv"
    target.write_text("old\n")

    def writer(tmp):
        tmp.write_text("half of the new")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write(target, writer)
    assert target.read_text() == "old\n"
    assert _leftovers(tmp_path) == []


def test_atomic_open_commits_only_on_success(tmp_path):
    target = tmp_path / "t.csv"
    with atomic_open(target, "w", newline="") as fh:
        fh.write("a,b\n1,2\n")
    assert target.read_text() == "a,b\n1,2\n"
    with pytest.raises(KeyError):
        with atomic_open(target, "w") as fh:
            fh.write("broken")
            raise KeyError("stop")
    assert target.read_text() == "a,b\n1,2\n"
    assert _leftovers(tmp_path) == []
    with pytest.raises(ValueError, match="write modes"):
        with atomic_open(target, "r"):
            pass


def test_atomic_write_text_unicode(tmp_path):
    p = atomic_write_text(tmp_path / "r.html", "omega\u2081 = 97 rad/s")
    assert p.read_text(encoding="utf-8") == "omega\u2081 = 97 rad/s"


@pytest.mark.parametrize("how", ["atomic_write", "atomic_open"])
def test_kill_during_write_leaves_the_old_file(tmp_path, how):
    """A writer process killed with SIGKILL in the middle of writing: the target still holds
    the complete old content (the in-place write this replaces left a 0-byte file)."""
    target = tmp_path / "map.nc"
    old = b"old complete content\n" * 100
    target.write_bytes(old)
    flag = tmp_path / "writing"
    code = textwrap.dedent(f"""
        import pathlib, time
        from maglev_match.core.io import atomic_open, atomic_write
        target = pathlib.Path({str(target)!r}); flag = pathlib.Path({str(flag)!r})
        def slow(fh):
            fh.write(b"new partial" * 1000); fh.flush()
            flag.write_text("1")
            time.sleep(60)
        if {how!r} == "atomic_write":
            def writer(tmp):
                with open(tmp, "wb") as fh:
                    slow(fh)
            atomic_write(target, writer)
        else:
            with atomic_open(target, "wb") as fh:
                slow(fh)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code])
    try:
        deadline = time.time() + 120
        while not flag.exists():
            assert proc.poll() is None, "writer ended early"
            assert time.time() < deadline
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert target.read_bytes() == old
    # the killed writer's partial data went to a temporary file beside it, never the target
    assert len(_leftovers(tmp_path)) == 1
    # the next write of that file removes the dead writer's temporary file, not a live one
    live = tmp_path / f".map.{os.getppid()}-abcd.tmp.nc"
    live.write_bytes(b"")
    atomic_write_text(target, "new")
    assert target.read_text() == "new"
    assert _leftovers(tmp_path) == [live.name]


# ---------------------------------------------------------------------------------------
# a full disk (issue 24)
# ---------------------------------------------------------------------------------------
def _enospc(*_a, **_k):
    raise OSError(28, "No space left on device")


@pytest.mark.parametrize("where", ["writer", "replace"])
def test_full_disk_is_disk_full_with_the_old_file_intact(tmp_path, monkeypatch, where):
    """ENOSPC inside the writer or at the final rename: DiskFull naming the target, the
    previous content untouched, no temporary file left."""
    from maglev_match.core import io as mio
    from maglev_match.core.io import DiskFull, is_disk_full

    target = tmp_path / "map.nc"
    target.write_bytes(b"old content")
    if where == "replace":
        monkeypatch.setattr(mio.os, "replace", _enospc)
    with pytest.raises(DiskFull) as err:
        atomic_write(target, (lambda tmp: _enospc()) if where == "writer"
                     else (lambda tmp: tmp.write_bytes(b"new")))
    assert str(err.value) == f"disk full: cannot write {target} (No space left on device)"
    assert not isinstance(err.value, OSError)  # never mistaken for a lost connection
    assert is_disk_full(err.value) and target.read_bytes() == b"old content"
    assert _leftovers(tmp_path) == []


def test_full_disk_in_atomic_open_and_a_quota(tmp_path, monkeypatch):
    import errno

    from maglev_match.core import io as mio
    from maglev_match.core.io import DiskFull

    target = tmp_path / "rows.csv"
    target.write_text("old\n")
    monkeypatch.setattr(mio.os, "fsync", lambda fd: (_ for _ in ()).throw(
        OSError(errno.EDQUOT, "Disk quota exceeded")))
    with pytest.raises(DiskFull, match="Disk quota exceeded"):
        with atomic_open(target, "w") as fh:
            fh.write("new\n")
    assert target.read_text() == "old\n" and _leftovers(tmp_path) == []


def test_netcdf_is_written_from_memory_and_reads_back(tmp_path, monkeypatch):
    """atomic_write_netcdf: the same dataset back (values, attributes), and HDF5 never
    touches the target path itself (a full disk is then a plain write error)."""
    import xarray as xr

    from maglev_match.core import io as mio
    from maglev_match.core.io import DiskFull, atomic_write_netcdf

    ds = xr.Dataset({"chi": (("y", "x"), np.arange(6.0).reshape(2, 3), {"units": "1"})},
                    coords={"x": [1.0, 2.0, 3.0], "y": [4.0, 5.0]}, attrs={"title": "t"})
    path = tmp_path / "m.nc"
    atomic_write_netcdf(path, ds)
    back = xr.load_dataset(path, engine="h5netcdf")
    xr.testing.assert_identical(back, ds)
    before = path.read_bytes()
    monkeypatch.setattr(mio.os, "fsync", _enospc)
    with pytest.raises(DiskFull):
        atomic_write_netcdf(path, ds.assign(chi=ds.chi * 2))
    assert path.read_bytes() == before and _leftovers(tmp_path) == []
