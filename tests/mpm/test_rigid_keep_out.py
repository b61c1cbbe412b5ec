"""A rigid body's bound (mpm.collider_motion.make_beyond): the keep-out
(mpm.keep_out) and the grid rule (mpm.collider_device.make_collide) do not
place a point beyond a body's reach from its centre, and that skips none
they act on: a particle just inside the farthest corners of a turned,
spinning box is put back on its surface, one just outside is left alone;
a node just outside a corner, within half a cell, is in contact."""

import numpy as np
import pytest
import warp as wp

import mpm
from mpm.colliders import Collider
from mpm.collider_device import make_collide, scene_kinds
from mpm.grid import make_boundary_data
from mpm.keep_out import make_keep_out
from mpm.materials import FixedCorotated
from mpm.stepping.status import StepStatus

pytest.importorskip("newton")

HALF, TURN, SPIN, CENTRE, TIME = (0.1, 0.05), 0.4, 3.0, (0.5, 0.5), 0.01


def placed_box():
    """A scene with one rigid box (half sizes HALF [m], turned by TURN
    [rad], spinning at SPIN [rad/s], float64), its record placed at the
    step's start t = 0: (model, solver, status)."""
    box = mpm.RigidBody(Collider.box(CENTRE, HALF), density=500.0, orientation=TURN, angular_velocity=SPIN)
    block = mpm.Body(mpm.Box((0.2, 0.2), (0.04, 0.04)), FixedCorotated(E=1e4, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, bodies=[block], gravity=(0.0, 0.0),
                      walls=("slip",) * 4, rigid_bodies=[box])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    status = solver.buffer.status
    solver.conditions.rigid.place(status)
    return model, solver, status


def corners(scale: float) -> np.ndarray:
    """The box's corners where it is at TIME (turned by TURN + SPIN TIME
    about its centre), at ``scale`` times the half diagonal from it."""
    angle = TURN + SPIN * TIME
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return CENTRE + scale * np.array([[sx * HALF[0], sy * HALF[1]] for sx in (-1, 1) for sy in (-1, 1)]) @ R.T


def kept_out(points: np.ndarray) -> np.ndarray:
    """``points`` after the keep-out at TIME [s] (:func:`placed_box`)."""
    model, solver, status = placed_box()
    t = model.types
    keep_out = make_keep_out(t, scene_kinds(model.scene), model.kernel.n_grids)
    Data = make_boundary_data(t)

    @wp.kernel
    def put_out(x: wp.array(dtype=t.vec), time: t.scalar, data: Data, status: StepStatus):
        p = wp.tid()
        lo = t.vec(t.scalar(-1.0), t.scalar(-1.0))
        y, v = keep_out(x[p], t.vec(), t.scalar(1.0), time, data, lo, -lo, status)
        x[p] = y

    x = wp.array(points, dtype=t.vec, device=model.device)
    wp.launch(put_out, len(points), inputs=[x, t.scalar(TIME), solver.conditions.data, status],
              device=model.device)
    return x.numpy()


def test_a_particle_inside_a_turned_box_corner_is_put_back_and_one_outside_is_not():
    """Each of the four corners of the box where it is at TIME (turned by
    TURN + SPIN TIME about its centre), 0.1 % of the half diagonal (the
    body's reach) inside it along the diagonal: put back on the surface,
    on a face to the rounding of the body's float32 pose (Newton's state:
    a few float32 epsilons of the reach); 0.1 % outside: not moved."""
    angle = TURN + SPIN * TIME
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    inside, outside = corners(0.999), corners(1.001)
    moved = kept_out(np.concatenate([inside, outside]))
    tol = 4 * np.finfo(np.float32).eps * np.hypot(*HALF)  # [m]
    local = (moved[:4] - CENTRE) @ R  # in the box's frame
    # on the surface: on a face's plane (|local_j| = half_j for one j) and within the other
    gap = np.min(np.abs(np.abs(local) - HALF), axis=1)
    assert np.all(gap < tol), gap
    assert np.all(np.abs(local) <= np.array(HALF) + tol)
    assert np.all(np.linalg.norm(moved[:4] - inside, axis=1) > 1e-5)  # they did move
    np.testing.assert_array_equal(moved[4:], outside)


def test_a_node_within_half_a_cell_of_a_turned_box_corner_is_in_contact():
    """A full node (body volume fraction 1) 0.4 dx beyond each corner of the
    box along its diagonal (its signed distance 0.4 dx: in contact,
    mpm.surface, though 0.4 dx = 11 % of the reach beyond the body's
    bound), moving into the box at 1 m/s: the grid rule changes its
    velocity, and gives the body an impulse."""
    model, solver, status = placed_box()
    t = model.types
    dx, reach = model.dx, float(np.hypot(*HALF))
    nodes = corners(1.0 + 0.4 * dx / reach)
    inward = (np.array(CENTRE) - nodes) / np.linalg.norm(np.array(CENTRE) - nodes, axis=1)[:, None]
    collide = make_collide(t, scene_kinds(model.scene))
    Data = make_boundary_data(t)

    @wp.kernel
    def grid_rule(q: wp.array(dtype=t.vec), v: wp.array(dtype=t.vec), time: t.scalar, data: Data,
                  status: StepStatus):
        i = wp.tid()
        v[i] = collide(v[i], q[i], t.scalar(1.0), t.scalar(1.0), t.mat(), time, data.colliders, data.profile,
                       status.collider_impulse, status.collider_torque)

    q = wp.array(nodes, dtype=t.vec, device=model.device)
    v = wp.array(inward, dtype=t.vec, device=model.device)
    status.collider_impulse.zero_()
    wp.launch(grid_rule, len(nodes), inputs=[q, v, t.scalar(TIME), solver.conditions.data, status],
              device=model.device)
    changed = np.linalg.norm(v.numpy() - inward, axis=1)
    assert np.all(changed > 0.1), changed  # the separating rule stops the approach along the normal
    assert np.abs(status.collider_impulse.numpy()).max() > 0.0
