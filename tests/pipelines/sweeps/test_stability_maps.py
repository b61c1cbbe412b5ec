"""The stability-map jobs (pipelines.run.stability_map) and the extreme-case
suite's configs."""

import numpy as np
import pytest

from helpers import compose_cfg, group_options, spec_for
from pipelines.config.validate import resolve


@pytest.mark.parametrize("scale", ["default", "paper"])
@pytest.mark.parametrize("case", group_options("extreme"))
def test_every_extreme_case_resolves(case, scale):
    """Each case of the suite composes with the experiment at both scales,
    validates, and states its expected outcome."""
    cfg = compose_cfg(["+experiment=extreme", f"+extreme={case}", f"scale={scale}"])
    assert cfg.expected and len(cfg.expected) > 20
    spec = resolve(cfg)
    assert spec.stability_map is None


def test_map_job_runs_its_points(tmp_path):
    """A stability-map job (pipelines.run.stability_map.run_map): every point runs at
    k times the CFL limit of its stiffness; below the limit the point
    completes, far above it the point stops unstable with its step and
    criterion; the job's metrics.json holds the map and the points' own
    metrics are not jobs of the sweep."""
    from pipelines.report.jobs import load_jobs
    from pipelines.report.sections.stability import largest_stable
    from pipelines.run.stability_map import run_map
    from pipelines.config.validate import MapSpec

    spec = spec_for(["scene=stability_ball_2d"])
    m = run_map(spec, MapSpec(E=[1e4, 1e8], dt_cfl=[0.5, 5.0], steps=10), tmp_path, {"config_hash": "h"})
    points = m["stability_map"]["points"]
    assert [(p["E"], p["k"]) for p in points] == [(1e4, 0.5), (1e4, 5.0), (1e8, 0.5), (1e8, 5.0)]
    for p in points:
        lam_2mu = p["E"] * 0.7 / (1.3 * 0.4)  # lambda + 2 mu at nu = 0.3
        c = np.sqrt(lam_2mu / 1000.0)  # P-wave speed [m/s]
        assert p["dt"] == pytest.approx(p["k"] * (1.0 / 32) / (c + 1.0))  # dx / (c + v0), v0 = 1 m/s
        if p["k"] < 1:
            assert p["status"] == "completed" and p["steps"] == 10
        else:
            assert p["status"] == "unstable" and 1 <= p["unstable_step"] < 10 and p["criterion"]
    assert largest_stable(points, 1e4) == 0.5
    assert m["status"] == "completed" and m["config_hash"] == "h"
    assert (tmp_path / "points" / "E10000_k0.5" / "point.json").is_file()
    jobs, _ = load_jobs(tmp_path)
    assert [j.rel for j in jobs] == ["."]


def test_the_maps_ball_is_excited_whatever_its_kernel(tmp_path):
    """The stability ball starts with a strain of 1e-6: with the linear
    kernel, whose stencil does not reach the floor's band, at E = 1e12 and
    k = 1.2 (above this ball's linear bound, 0.93: pipelines.cfl_bound) the
    point stops unstable within a few steps (measured: step 8); the same
    ball without the strain translates rigidly, nothing excites the
    unstable mode, and the point "completes" its steps. (On the floor of
    earlier versions, scene.boundary_rule=nodes, where the maps were
    measured; on the floor where a body touches, the ball's sampled volume
    reaches the floor's face from the first step, and the floor excites it.)"""
    import dataclasses

    from pipelines.recording.sinks import Sink
    from pipelines.run.runner import execute
    from pipelines.run.stability_map import point_spec

    spec = spec_for(["scene=stability_ball_2d", "kernel=linear", "scene.boundary_rule=nodes"])
    assert spec.scene.bodies[0].deformation is not None
    m = execute(point_spec(spec, 1e12, 1.2, 60), tmp_path / "seeded", sink=Sink())
    assert m["status"] == "unstable" and m["unstable_step"] < 30, m.get("reason")
    rigid = dataclasses.replace(spec, scene=dataclasses.replace(
        spec.scene, bodies=[dataclasses.replace(b, deformation=None) for b in spec.scene.bodies]))
    m = execute(point_spec(rigid, 1e12, 1.2, 60), tmp_path / "rigid", sink=Sink())
    assert m["status"] == "completed" and m["steps"] == 60
