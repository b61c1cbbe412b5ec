"""The rigid bodies' speed in the step rule (mpm.rigid_coupling): a body's
surface moves at most the CFL number of cells per step, as a particle does,
whether it translates or spins, from the first step on."""

import math

import numpy as np
import pytest

import mpm
from mpm.colliders import Collider
from mpm.materials import FixedCorotated

pytest.importorskip("newton")

CFL = 0.4


class Steps(mpm.Observer):
    """Each step's length [s] and the body's speed and spin at its start."""

    def __init__(self):
        self.dt, self.v, self.w = [], [], []

    def on_step(self, driver, report):
        p = driver.solver.conditions.rigid.poses()
        self.dt.append(report.dt)
        self.v.append(np.linalg.norm(p["velocity"][0]))
        self.w.append(np.linalg.norm(p["angular_velocity"][0]))

    def wants(self, driver):
        return driver.step + 1, math.inf


@pytest.mark.parametrize("velocity, spin", [((20.0, 0.0), 0.0), ((0.0, 0.0), 400.0)])
def test_a_fast_body_moves_at_most_the_cfl_number_of_cells_a_step(velocity, spin):
    """A disc (r = 0.05 m) at 20 m/s, or spinning at 400 rad/s (its rim at
    20 m/s), near an elastic block at rest (wave speed 3.7 m/s), 32 cells:
    every step is at most CFL dx / (c + |v| + |omega| r), so that its
    surface moves at most 0.4 cell a step (before the bodies entered the
    rule, the particles at rest left the step at the rule's largest, 1 ms:
    0.64 cell a step)."""
    r = 0.05
    disc = mpm.RigidBody(Collider.sphere((0.3, 0.5), r, boundary="separate"), density=1000.0,
                         velocity=velocity, angular_velocity=spin)
    material = FixedCorotated(E=1e4, nu=0.3, rho=1000.0)
    block = mpm.Body(mpm.Box((0.75, 0.5), (0.1, 0.1)), material)
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, bodies=[block], gravity=(0.0, 0.0),
                      walls=("slip",) * 4, rigid_bodies=[disc])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    steps = Steps()
    driver = mpm.Driver(mpm.Solver(model, mpm.EMPM()), state, mpm.StepPolicy(steps=20, cfl=CFL), observers=[steps])
    assert driver.run().status == "completed"
    c = material.wave_speed(1.0)
    dt = np.array(steps.dt)
    surface = np.array([20.0] + [v + w * r for v, w in zip(steps.v, steps.w)][:-1])  # at each step's start
    assert len(dt) == 20 and surface.min() > 19.0
    assert np.all(dt * (c + surface) <= CFL * model.dx * (1 + 1e-6)), dt * surface / model.dx  # (float32 state)
    assert np.all(dt * (c + surface) >= 0.99 * CFL * model.dx)  # the body, not something else, sets it
