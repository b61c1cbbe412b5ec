"""The GPU session's kit (pipelines.bench.gpu_kit) on a stand-in
site-packages: packed in two halves, joined and checked there, and the
session's steps each under a time limit."""

import sys

import pytest

from pipelines.bench import gpu_kit


def _site(root):
    """A stand-in site-packages: the four packages, warp's CUDA library, and what pack leaves out."""
    for name in gpu_kit.PACKAGES:
        (root / name).mkdir(parents=True)
        (root / name / "__init__.py").write_text(f"NAME = {name!r}\n")
    (root / "warp" / "bin").mkdir()
    (root / "warp" / "bin" / "warp.so").write_bytes(bytes(range(256)) * 4000)  # 1 MB, not all alike
    (root / "warp" / "bin" / "warp-clang.so").write_bytes(b"cpu compiler")
    (root / "warp" / "tests").mkdir()
    (root / "warp" / "tests" / "t.py").write_text("")
    return root


def test_the_kit_travels_in_two_halves_and_joins_there(tmp_path):
    site = _site(tmp_path / "site")
    parts = tmp_path / ".gpu"
    files = gpu_kit.pack(parts, site)
    assert {f.relative_to(parts).as_posix() for f in files} == {
        "a/site.tar.xz", "a/warp.so.xz.0", "a/warp.so.sha256", "b/warp.so.xz.1"}
    # the first call keeps a/ on the machine; the second carries b/ only
    kit = tmp_path / "kit"
    gpu_kit.keep_first_half(parts, kit)
    (parts / "a" / "warp.so.xz.0").unlink()
    out = gpu_kit.unpack(kit, parts, tmp_path / "gpu-site")
    assert (out / "warp" / "bin" / "warp.so").read_bytes() == (site / "warp" / "bin" / "warp.so").read_bytes()
    assert (out / "hydra" / "__init__.py").read_text() == "NAME = 'hydra'\n"
    # left out: the CPU compiler and warp's tests
    assert not (out / "warp" / "bin" / "warp-clang.so").exists() and not (out / "warp" / "tests").exists()


def test_a_damaged_half_is_refused(tmp_path):
    site = _site(tmp_path / "site")
    parts = tmp_path / ".gpu"
    gpu_kit.pack(parts, site)
    (parts / "a" / "warp.so.sha256").write_text("0" * 64 + "\n")
    with pytest.raises(SystemExit, match="SHA-256 differs"):
        gpu_kit.unpack(tmp_path / "kit", parts, tmp_path / "gpu-site")


def test_a_session_step_that_runs_out_of_time_does_not_stop_the_next(tmp_path):
    steps = (("slow", f"{sys.executable} -c 'import time; time.sleep(5)'", 1),
             ("path", "{py} -c 'import hydra; print(hydra.NAME)'", 30))
    site = _site(tmp_path / "site")
    failed = gpu_kit.session(tmp_path / "out", False, site, steps=steps)
    log = (tmp_path / "out" / "session.log").read_text()
    assert failed == 1
    assert "=== slow: timed out" in log and "=== path: 0 after" in log and "\nhydra\n" in log
