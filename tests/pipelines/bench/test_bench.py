"""The bench's accounting (pipelines.bench.scale, mpm.memory): launches per
step, the arrays a run holds. Speed itself is measured by the bench, not here."""

import json
import time

import pytest
import warp as wp

import mpm
from helpers import DEVICE, spec_for
from mpm.memory import array_bytes
from pipelines.bench import scale as bench_scale
from pipelines.run.runner import execute, solver_options
from pipelines.recording.sinks import Sink

SMALL = ["scene=elastic_ball_2d", "scene.resolution=32", "scheme=empm", "detect.action=off"]


def test_a_step_launches_only_the_stages_the_scene_needs():
    """One body, explicit EMPM: P2G, grid update, G2P (which does the
    configuration update with the quadratic kernel; the compact kernel's is a
    launch of its own), the criterion and the driver's policy (one thread
    each, mpm.stepping.criterion, mpm.stepping.policy). Two bodies with contact add splat,
    correct, clear and the boundary pass (mpm.stepping.plan). At k = 1 the host reads
    the step's history row once and nothing else; at k = 10 once per batch."""
    launches, _, reads = bench_scale.launches_per_step(spec_for(SMALL), steps=3)
    assert launches == 3 + 2 and reads == 1
    launches, _, _ = bench_scale.launches_per_step(spec_for(SMALL + ["kernel=compact"]), steps=3)
    assert launches == 4 + 2
    two = SMALL + [bench_scale.TWO_BALLS, "scene.contact=frictionless"]
    launches, _, _ = bench_scale.launches_per_step(spec_for(two), steps=3)
    assert launches == 3 + 3 + 1 + 2
    launches, _, _ = bench_scale.launches_per_step(spec_for(two + ["run.fuse=false"]), steps=3)
    assert launches == 3 + 3 + 1 + 2 + 2  # and an update per body
    # TLMPM never updates its configuration
    launches, _, _ = bench_scale.launches_per_step(spec_for(SMALL + ["scheme=tlmpm"]), steps=3)
    assert launches == 3 + 2
    launches, _, reads = bench_scale.launches_per_step(spec_for(SMALL), steps=30, sync_every=10)
    assert launches == 3 + 2 and reads == 0.1


def test_memory_counts_each_array_once():
    """array_bytes: the distinct arrays reachable from the roots, a view and a
    repeated reference counted once; a run's arrays at least hold the state."""
    with wp.ScopedDevice(DEVICE):
        a = wp.zeros(100, dtype=wp.float32)
        b = wp.zeros((10, 3), dtype=wp.float64)
    assert array_bytes(a, b) == 400 + 240
    assert array_bytes([a, a[10:], {"b": b, "again": b}]) == 640
    spec = spec_for(SMALL)
    model, state = mpm.build(spec.scene, spec.kernel, "float32", DEVICE)
    solver = mpm.Solver(model, spec.scheme, solver_options(spec))
    solver.prepare(state)
    state_bytes = sum(getattr(state, k).capacity for k in ("x", "v", "C", "F0s", "Fsn", "X"))
    assert solver.memory_bytes(state) > state_bytes + model.mass.capacity + solver.grid.v.capacity


def test_metrics_report_memory(tmp_path):
    """metrics.json: the run's arrays [MB] (grids at capacity) and the
    process's peak resident memory, which holds them."""
    m = execute(spec_for(SMALL + ["run.steps=2"]), tmp_path, sink=Sink())
    assert m["status"] == "completed"
    n = m["particles"]
    # per particle at least x, v, X (2 floats each), C, F0s, Fsn (4 each), mass and volume
    assert m["memory_mb"] * 1e6 >= n * 4 * (3 * 2 + 3 * 4 + 2)
    assert m["peak_rss_mb"] > m["memory_mb"]


def test_the_fused_eulerian_path_holds_no_stencil_cache():
    """EMPM fused (the default with the quadratic kernel) keeps no per-particle
    stencils: it holds less than the cached path by at least the cache's
    first nodes, coordinates and weights (and slopes) per particle."""
    held, stencils = {}, {}
    for fuse in (True, False):
        spec = spec_for(SMALL + [f"run.fuse={str(fuse).lower()}"])
        model, state = mpm.build(spec.scene, spec.kernel, "float32", DEVICE)
        solver = mpm.Solver(model, spec.scheme, solver_options(spec))
        solver.prepare(state)
        assert solver.fused == fuse
        held[fuse] = solver.memory_bytes(state)
        stencils[fuse] = sum(getattr(state.stencils, k).capacity for k in ("base", "fx", "W", "dW"))
    assert stencils[False] >= model.n_particles * 4  # the cached run holds a first node per particle
    assert held[False] - held[True] >= stencils[False] - stencils[True]


@pytest.mark.slow
def test_the_precision_table_times_each_variant_in_the_same_rounds(tmp_path, monkeypatch):
    """pipelines.bench's precision table: plain float32, compensated float32
    and float64 of one case, each a completed run, ratios to plain float32
    from the same rounds (one small case, one round, here)."""
    from pipelines.bench import precision

    monkeypatch.setattr(precision, "CASES", {"ball_2d": (["scene=elastic_ball_2d", "scene.resolution=16"], 3)})
    monkeypatch.setattr(precision, "SCHEMES", ("tlmpm",))
    monkeypatch.setattr(precision, "ROUNDS", 1)
    rows = precision.bench_precision(tmp_path)
    assert [r["variant"] for r in rows] == list(precision.VARIANTS)
    assert rows[0]["vs_float32"] == 1.0 and all(r["step_ms"] > 0 for r in rows)
    assert len({r["particles"] for r in rows}) == 1  # the same case in every variant
    # each variant ran as named: its run's metrics.json (the rounds' runs, in order of VARIANTS)
    runs = [json.loads((tmp_path / "precision_ball_2d_tlmpm" / f"{i}_0" / "metrics.json").read_text())
            for i in range(len(rows))]
    ran = [(m["precision"], m["precision_check"]["compensate"]) for m in runs]
    assert ran == [("float32", False), ("float32", True), ("float64", False)], ran
    assert [m["particles"] for m in runs] == [r["particles"] for r in rows]


def test_the_large_table_reports_rate_reads_and_memory():
    """``--large``'s rows at a small size: steps per second from the timed
    steps, the host's reads per step (every step on the CPU), the arrays' MB."""
    start = time.perf_counter()
    rows = bench_scale.bench_large(steps=3, rounds=1, sizes={"tiny": 16})
    elapsed = time.perf_counter() - start
    (r,) = rows
    assert r["particles"] > 100 and r["device"] == DEVICE
    # the timed steps lie within the call's own wall time, set-up excluded
    assert 0.0 < 3 * r["step_ms"] / 1e3 <= elapsed - r["setup_s"]
    if DEVICE == "cpu":  # one read-back per step on the CPU (no batches there)
        assert r["sync_every"] == 1 and r["reads"] == pytest.approx(1.0)
    # the arrays: at least the particles' positions, velocities, C and two F in float32 (2 + 2 + 3 x 4 floats)
    assert r["arrays_mb"] * 1e6 >= r["particles"] * 4 * (2 + 2 + 3 * 4)


def test_the_bench_runs_without_rerun_sdk_when_asked(tmp_path):
    """``--no-recording``: no run imports rerun (a machine without rerun-sdk,
    such as a bare GPU node, can run the step-only tables)."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['rerun'] = None; sys.modules['rerun_bindings'] = None\n"
            "from pipelines.bench.__main__ import main\n"
            f"main(['ball_2d', '--only', 'speed', '--steps', '3', '--no-recording', '--device', '{DEVICE}'])\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    row = next(line for line in r.stdout.splitlines() if line.startswith("ball_2d"))
    assert row.split()[-3:] == ["-", "-", "-"]  # no logged columns


@pytest.mark.slow
def test_the_sweep_table_times_whole_sweeps(tmp_path, monkeypatch):
    """The sweep table runs real multirun commands: 2N jobs per worker count,
    runs per hour from the wall time (N = 1 here: one row, ratio 1)."""
    from pipelines.bench import throughput

    monkeypatch.setattr(throughput, "CASE", [c.replace("run.duration=0.5", "run.steps=5") for c in throughput.CASE])
    start = time.perf_counter()
    (r,) = throughput.bench_sweep(tmp_path, cores=1)
    elapsed = time.perf_counter() - start
    assert r["jobs"] == 2 and r["workers"] == 1 and r["vs_one"] == 1.0
    assert 0.0 < r["wall_s"] <= elapsed  # the sweep's own wall time, within the call's
    jobs = sorted(p for p in (tmp_path / "sweep_1").iterdir() if p.is_dir())
    assert [p.name for p in jobs] == ["0", "1"]
    metrics = [json.loads((p / "metrics.json").read_text()) for p in jobs]
    assert all(m["status"] == "completed" and m["steps"] == 5 for m in metrics), metrics
    # each job's own run time fits in the sweep's wall time (one worker: one after the other)
    assert sum(m["wall_time_s"] for m in metrics) <= r["wall_s"]


def test_the_peers_table_says_when_taichi_is_missing(tmp_path, monkeypatch):
    """Without taichi the peers table is one row saying so (taichi is not a dependency)."""
    import sys

    from pipelines.bench import peers

    monkeypatch.setitem(sys.modules, "taichi", None)
    assert peers.bench_peers(tmp_path, DEVICE) == [{"peer": "taichi", "missing": True}]


def test_the_genesis_peer_gets_the_bench_ball_and_one_thread(tmp_path, monkeypatch):
    """The Genesis peer (run by another Python; here this one with a
    stand-in genesis package, tests/pipelines/bench/stub_genesis) is given
    the bench's 3D ball: 64 cells per metre, particles dx / 2 apart (8 per
    cell, as ours), the ball's E, nu, density, centre and radius, a
    corotated elastic law, one substep per step, one thread."""
    import json
    import sys
    from pathlib import Path

    from pipelines.bench import peers

    log = tmp_path / "genesis.json"
    monkeypatch.setenv("PYTHONPATH", str(Path(__file__).with_name("stub_genesis")))
    monkeypatch.setenv("STUB_GENESIS_LOG", str(log))
    monkeypatch.delenv("QD_NUM_THREADS", raising=False)
    out = peers.genesis_ball(sys.executable, steps=20)
    seen = json.loads(log.read_text())
    assert seen["init"]["backend"] == "cpu" and seen["init"]["threads"] == "1"
    assert seen["mpm"]["grid_density"] == 64 and seen["mpm"]["particle_size"] == pytest.approx(1 / 128)
    assert seen["mpm"]["upper_bound"] == [1.0, 1.0, 1.0]
    assert seen["material"] == {"E": 1e5, "nu": 0.3, "rho": 1000.0, "model": "corotation"}
    assert seen["sphere"] == {"pos": [0.5, 0.55, 0.5], "radius": 0.2}
    assert seen["sim"]["substeps"] == 1 and seen["sim"]["gravity"] == [0.0, -9.81, 0.0]
    assert out["particles"] == round((4 / 3) * 3.141592653589793 * 0.2 ** 3 * 128 ** 3)
    assert out["ms_per_step"] >= 0.0 and out["threads"] == 1


def test_the_genesis_peer_is_not_measured_without_its_python(tmp_path):
    from pipelines.bench import peers

    assert peers.bench_genesis(tmp_path, None) == [{"peer": "genesis", "missing": True}]


def test_the_order_table_steps_the_same_particles_in_another_order(tmp_path):
    """The permuted run is the same system: after 5 steps its particles,
    sorted back by reference position X, have the sampled run's positions
    and velocities (to float32 rounding: the grid sums in another order)
    and the same masses."""
    import numpy as np

    from pipelines.bench import order

    case = ["scene=elastic_ball_3d", "scene.resolution=16", "material=fixed_corotated", "scheme=empm"]
    a, b = order._driver(DEVICE, False, case), order._driver(DEVICE, True, case)

    def by_X(d):
        X = d.state.X.numpy()
        k = np.lexsort(X.T)
        return X[k], d.state.x.numpy()[k], d.state.v.numpy()[k], d.solver.model.mass.numpy()[k]

    (Xa, xa, va, ma), (Xb, xb, vb, mb) = by_X(a), by_X(b)
    assert not np.array_equal(a.state.X.numpy(), b.state.X.numpy())  # the order did change
    assert np.array_equal(Xa, Xb) and np.array_equal(ma, mb)
    np.testing.assert_allclose(xb, xa, atol=1e-6)  # [m], a 1 m box in float32
    np.testing.assert_allclose(vb, va, atol=1e-4 * max(1.0, np.abs(va).max()))
    rows = order.bench_order(DEVICE, rounds=1, steps=2, case=case)
    assert [r["order"] for r in rows] == ["sampled", "random"] and rows[0]["vs_sampled"] == 1.0


def test_a_failing_genesis_peer_is_one_line_in_its_table(tmp_path, monkeypatch, capsys):
    """Genesis breaking in its own process ends neither the bench nor its
    other tables: the table's row names the failure in one line."""
    import sys
    from pathlib import Path

    from pipelines.bench import peers

    monkeypatch.setenv("PYTHONPATH", str(Path(__file__).with_name("stub_genesis")))
    monkeypatch.setenv("STUB_GENESIS_LOG", str(tmp_path / "genesis.json"))
    monkeypatch.setenv("STUB_GENESIS_FAIL", "1")
    monkeypatch.setattr(peers, "interleaved", lambda *a, **k: {"ours": {"step_time_ms": 1.0, "particles": 10}})
    rows = peers.bench_genesis(tmp_path, sys.executable, rounds=1)
    assert rows[0]["failed"].startswith("the Genesis peer failed")
    peers.print_genesis(rows)
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1].startswith("genesis not measured: the Genesis peer failed") and "stub genesis" in out[-1]


@pytest.mark.slow
def test_the_checkpoint_table_writes_one_after_every_step_and_resumes_the_last(tmp_path, monkeypatch, capsys):
    """Each case's run writes a checkpoint per step (the mean write, the newest file's size), and its
    continuation starts from the one before the end; the default interval's share is write / 300 s."""
    from helpers import ROOT
    from pipelines.bench import checkpoint
    from pipelines.run import checkpoints

    monkeypatch.chdir(ROOT)
    monkeypatch.setattr(checkpoint, "CASES", {"tiny": (["scene.resolution=16", "log.every=1"], 4)})
    (row,) = checkpoint.bench_checkpoint(tmp_path)
    assert row["resumed_at"] == [3] and row["bytes"] > 1000 and 0 < row["write_s"] < 10
    assert row["fraction"] == row["write_s"] / checkpoints.AUTO_WALL_S and row["resumed_startup_s"] > 0
    checkpoint.print_checkpoint([row])
    assert "tiny" in capsys.readouterr().out
