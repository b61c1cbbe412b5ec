"""Contact between bodies holds water: water at rest in a thin-walled cup
that is a second body (not a collider) stays in it, in every scheme."""

import numpy as np
import pytest

import mpm

RES = 32
DX = 1.0 / RES
INNER = (0.3, 0.7)  # the cup's inner faces along x [m]
FLOOR = 0.1875  # the cup's inner floor [m]; the domain's floor band ends at 3 cells (0.094 m)
DEPTH, FILL = 0.3, 0.2  # the cup's inner depth and the water's [m]


def cup_scene(wall: float) -> mpm.Scene:
    """A stiff neo-Hookean cup (E = 3e7 Pa: its walls, cantilevers 0.3 m tall
    and a few centimetres thick, bend by about a millimetre under the water's
    pressure; at 3e5 Pa they fold outwards) set just above the domain's
    sticky floor band, filled to 0.2 m with water (K = 1e5 Pa) at rest; the bodies meet
    by frictionless contact."""
    x0, x1 = INNER
    mid, half = (x0 + x1) / 2, (x1 - x0) / 2
    cup = mpm.Compound((mpm.Box((mid, FLOOR - wall / 2), (half + wall, wall / 2)),
                        mpm.Box((x0 - wall / 2, FLOOR + DEPTH / 2), (wall / 2, DEPTH / 2)),
                        mpm.Box((x1 + wall / 2, FLOOR + DEPTH / 2), (wall / 2, DEPTH / 2))))
    water = mpm.Box((mid, FLOOR + FILL / 2), (half, FILL / 2))
    return mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=RES, ppc=4, gravity=(0.0, -9.81),
                     walls=("slip", "slip", "sticky", "slip"),
                     bodies=[mpm.Body(water, mpm.Fluid(rho=1000.0, K=1.0e5, gamma=7.0), name="water"),
                             mpm.Body(cup, mpm.NeoHookean(E=3.0e7, nu=0.3, rho=1000.0), name="cup")])


@pytest.mark.parametrize("cells", [2.5, 1.5])
@pytest.mark.parametrize("scheme", [mpm.EMPM(), mpm.TLMPM(), mpm.AULMPM()], ids=lambda s: s.name)
def test_water_stays_in_a_thin_walled_cup(scheme, cells, device):
    """Every 0.05 s over 0.3 s: no water particle lies outside the cup's
    walls (beyond the cup particles' extent along x, or below its lowest
    particle) or in them (beyond their inner faces by half a cell), and the water's surface is level - the highest water particle
    over each of eight columns across the cup within a cell of the others
    (the water starts without its weight's compression and sloshes by less
    than that). Walls of 2.5 and 1.5 cells."""
    model, state = mpm.build(cup_scene(cells * DX), mpm.QUADRATIC, "float32", device)
    solver = mpm.Solver(model, scheme)
    (ws, wn), (cs, cn) = model.body_ranges
    columns = np.linspace(INNER[0] + DX, INNER[1] - DX, 8)
    for _ in range(6):
        driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=0.05))
        assert driver.run().status == "completed"
        x = state.x.numpy().astype(np.float64)
        water, cup = x[ws:ws + wn], x[cs:cs + cn]
        outside = (water[:, 0] < cup[:, 0].min()) | (water[:, 0] > cup[:, 0].max()) | (water[:, 1] < cup[:, 1].min())
        assert not outside.any(), f"{outside.sum()} water particles outside the cup at t = {solver.time:.2f} s"
        # nor in a wall: beyond its inner face (the wall particles' extent now) by half a cell
        walls = cup[:, 1] > FLOOR + DX
        left, right = cup[walls & (cup[:, 0] < 0.5), 0].max(), cup[walls & (cup[:, 0] > 0.5), 0].min()
        floor = cup[~walls & (np.abs(cup[:, 0] - 0.5) < 0.1), 1].max()
        inside = (water[:, 0] > left - DX / 2) & (water[:, 0] < right + DX / 2) & (water[:, 1] > floor - DX / 2)
        assert inside.all(), f"{(~inside).sum()} water particles in the cup's walls at t = {solver.time:.2f} s"
        surface = [water[np.abs(water[:, 0] - c) < DX / 2, 1].max() for c in columns]
        assert max(surface) - min(surface) < DX, surface
