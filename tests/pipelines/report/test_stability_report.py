"""The stability maps' and the extreme suite's report sections over a
synthetic sweep (stability.md)."""


def _map_job(root, name, kernel, rows):
    from test_report import _job

    m = {"status": "completed", "reason": "", "steps": 10, "sim_time": 0.0, "scene": "stability_ball_2d",
         "scheme": "empm", "kernel": kernel, "transfer": "mls", "integrator": "explicit",
         "config_hash": name,
         "stability_map": {"E": [1e3, 1e6], "dt_cfl": [0.5, 1.0, 2.0], "steps": 10, "points": rows}}
    return _job(root, name, m, ["scene=stability_ball_2d", f"kernel={kernel}", "+experiment=stability"])


def _point(E, k, status, step=None, criterion=None):
    return {"E": E, "k": k, "dt": k * 1e-4, "status": status, "steps": 10 if step is None else step,
            "unstable_step": step, "criterion": criterion, "body": None, "reason": "", "wall_time_s": 0.1}


def test_report_reads_a_synthetic_stability_sweep(tmp_path):
    """Two maps and two extreme-suite jobs: stability.md tabulates the
    largest stable multiple per combination and stiffness (a failure
    below a stable point counts), draws the heat maps, and lists the suite
    with the outcome and the expected text."""
    import json

    from pipelines.report import write_report
    from test_report import _job

    ok, bad = "completed", "unstable"
    _map_job(tmp_path, "a", "quadratic", [
        _point(1e3, 0.5, ok), _point(1e3, 1.0, ok), _point(1e3, 2.0, bad, 3, "energy"),
        _point(1e6, 0.5, ok), _point(1e6, 1.0, bad, 5, "speed"), _point(1e6, 2.0, ok)])
    _map_job(tmp_path, "b", "cubic", [
        _point(1e3, 0.5, bad, 1, "outside"), _point(1e3, 1.0, ok), _point(1e3, 2.0, ok),
        _point(1e6, 0.5, ok), _point(1e6, 1.0, ok), _point(1e6, 2.0, ok)])
    for scheme, status in (("empm", "completed"), ("tlmpm", "unstable")):
        m = {"status": status, "reason": "", "steps": 40, "sim_time": 0.01, "scene": "elastic_ball_2d",
             "scheme": scheme, "kernel": "quadratic", "transfer": "mls", "config_hash": f"x{scheme}",
             "energy_initial": 10.0, "energy_final": 9.0, "fracture": {"total": 0.25},
             "detect": {"energy_scale": 4.0, "energy_growth_max": 0.0},
             "unstable_criterion": "inversion", "unstable_step": 7}
        d = _job(tmp_path, f"x{scheme}", m, ["+extreme=compressed_start", f"scheme={scheme}",
                                             "+experiment=extreme"])
        (d / ".hydra" / "config.yaml").write_text("expected: springs back\n"
                                                  "scene: {name: elastic_ball_2d}\n")
    write_report(tmp_path)
    text = (tmp_path / "stability.md").read_text()
    assert "| empm · quadratic · mls · explicit | 1 | 0.5 |" in text
    assert "| empm · cubic · mls · explicit | <0.5 | 2 |" in text
    assert (tmp_path / "stability_stability_ball_2d.png").stat().st_size > 10_000
    assert "| compressed_start | empm | completed | 40 | 0.01 | -0.25 | 0 | 0.25 |" in text
    assert "| compressed_start | tlmpm | unstable (inversion, step 7) |" in text
    assert "- `compressed_start`: springs back" in text
    rows = (tmp_path / "stability.csv").read_text().splitlines()
    assert len(rows) == 1 + 12
    assert "Stability maps" in (tmp_path / "report.md").read_text()
    assert json.loads((tmp_path / "a" / "metrics.json").read_text())["stability_map"]["steps"] == 10
