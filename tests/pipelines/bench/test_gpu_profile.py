"""The per-kernel profile's accounting (pipelines.bench.gpu_profile): the
compulsory bytes of a launch, the rows of a small sphere. Speed itself is
measured by the bench, not here."""

import pytest
import warp as wp

from helpers import DEVICE
from pipelines.bench import gpu_profile
from pipelines.bench.__main__ import main


def test_a_launch_moves_each_array_once_over_its_extent():
    """min(elements, launch size) x element bytes per distinct array, struct
    fields included; the same array passed twice counts once."""

    @wp.struct
    class Holder:
        a: wp.array(dtype=wp.vec3)
        s: float

    x = wp.zeros(100, dtype=wp.float32, device=DEVICE)
    grid = wp.zeros(1000, dtype=wp.vec3, device=DEVICE)
    h = Holder()
    h.a, h.s = grid, 1.0
    # a launch of 100 threads: x whole (100 x 4 B), the grid's first 100 vec3 (100 x 12 B), x again nothing
    assert gpu_profile.launch_bytes(100, [x, h, x, 3.0]) == 100 * 4 + 100 * 12
    # a launch of 2000 threads touches at most each array's size
    assert gpu_profile.launch_bytes((20, 100), [x, grid]) == 100 * 4 + 1000 * 12


def test_the_profile_accounts_for_the_whole_step():
    """A small sphere: every solver kernel has a row; the device rows and the
    host row add up to the step; the step's bytes are the kernels' sum; a
    step moves at least each particle's x, v, C and F once (float32)."""
    rows = gpu_profile.gpu_profile(sizes=("16",), steps=3, rounds=1)
    step = rows[-1]
    assert step["part"] == "step" and step["device"] == DEVICE
    parts = rows[:-1]
    names = [r["part"] for r in parts]
    assert any(n.endswith("p2g") for n in names) and any(n.endswith("g2p") for n in names)
    # each launch is timed inside the step's wall time: the host keeps a share, no kernel exceeds the step
    host = next(r for r in parts if r["part"].startswith("host"))
    assert host["ms"] >= 0.0
    kernels = [r for r in parts if r["mb"] is not None]
    assert all(0.0 < r["ms"] <= step["ms"] for r in kernels)
    # G2P alone reads or writes each particle's x, v and C (float32, 3D) at least once
    g2p = next(r for r in kernels if r["part"].endswith("g2p"))
    assert g2p["mb"] * 1e6 >= step["particles"] * 4 * (3 + 3 + 9)
    assert step["mb"] * 1e6 >= step["particles"] * 4 * (3 + 3 + 9 + 9)
    assert step["copy_gb_s"] > 0 and step["particle_steps_per_s"] > 0
    assert all(r["launches"] >= 1 for r in kernels)


def test_a_bad_profile_size_is_one_line(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--only", "gpu-profile", "--profile-sizes", "1K"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--profile-sizes: '1K'; accepted: 1M, 10M or a resolution >= 8" in err
