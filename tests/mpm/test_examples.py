"""The examples in examples/ run, and what they compute is right."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_drop_ball_falls_freely_under_the_driver(device):
    """The disc falls freely until it reaches the floor's wall band: its
    centre of mass follows y0 - g t^2 / 2 (symplectic Euler's error is below
    g dt t, dt the largest step), it starts from rest, the kinetic plus
    potential energy of the fall changes by less than the same order
    (m g^2 dt t), and every step obeys the explicit rule (dt <= cfl dx / c)."""
    example = load("drop_ball")
    driver, tr = example.drop(duration=0.15, scheme="aulmpm", device=device)
    assert driver.outcome.status == "completed" and driver.step == len(tr.t) - 1
    assert abs(driver.time - 0.15) <= 1e-12
    g, dt = 9.81, max(driver.dts)
    m = tr.mass.sum()
    c = driver.solver.model.scene.bodies[0].material.wave_speed()
    assert dt <= 0.4 * driver.solver.model.dx / c
    t = np.array(tr.t)
    y = np.array([p[1] for p in tr.center])
    np.testing.assert_allclose(y, y[0] - 0.5 * g * t**2, rtol=0, atol=g * dt * t.max() + 1e-6)
    assert tr.kinetic[0] == 0.0
    E = np.add(tr.kinetic, tr.potential)
    assert np.abs(E - E[0]).max() <= m * g**2 * dt * t.max()


def test_drop_ball_script_prints_its_outcome():
    """``python examples/drop_ball.py`` runs as a script and reports a completed run.
    A script's own folder comes first on its path, not the working directory:
    PYTHONPATH names the checkout, so that the script imports this checkout's
    packages (as the tests do), not another installed copy."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "drop_ball.py"), "--duration", "0.3"],
                         capture_output=True, text=True, timeout=600, cwd=ROOT, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("completed after") and "at the floor" in out.stdout
