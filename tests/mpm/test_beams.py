"""The beam references of the load benchmarks (mpm.beams) against
published values and against each other."""

import pytest

from mpm.beams import bar_wave, cantilever_tip, elastica_tip, plane_moduli

# Tip of a cantilever elastica under a dead tip load, (P L^2 / EI, deflection / L,
# shortening / L), as tabulated by Mattiasson (1981, Int. J. Numer. Methods Eng. 17,
# 145-153, Table I) from the elliptic-integral solution of Bisshopp & Drucker (1945)
PUBLISHED = [(1.0, 0.30172, 0.05643), (2.0, 0.49346, 0.16064), (3.0, 0.60325, 0.25442),
             (5.0, 0.71379, 0.38763), (10.0, 0.81061, 0.55500)]


@pytest.mark.parametrize("alpha, deflection, shortening", PUBLISHED)
def test_elastica_matches_the_published_table(alpha, deflection, shortening):
    """The shooting solution (RK4, 2000 steps) agrees with the table to its 5 digits."""
    v, h = elastica_tip(alpha)
    assert v == pytest.approx(deflection, abs=1e-5)
    assert h == pytest.approx(shortening, abs=1e-5)


def test_small_loads_recover_euler_bernoulli():
    """As P -> 0 the elastica's deflection / L tends to alpha / 3 (EB: P L^3 / 3 EI)
    and its shortening is of second order (below 1 % of the deflection at
    alpha = 1e-3); 2D elasticity adds the shear term (4 + 5 nu') P L / (2 E' H)."""
    alpha = 1e-3
    v, h = elastica_tip(alpha)
    assert v == pytest.approx(alpha / 3, rel=1e-5)
    assert h < 1e-2 * v
    ref = cantilever_tip(P=4.0, L=0.8, H=0.1, E=1e6, nu=0.0)
    assert ref["euler_bernoulli"] == pytest.approx(4.0 * 0.8**3 / (3 * 1e6 * 0.1**3 / 12), rel=1e-14)
    assert ref["elasticity"] - ref["euler_bernoulli"] == pytest.approx(2.0 * 4.0 * 0.8 / (1e6 * 0.1), rel=1e-12)


def test_plane_strain_moduli_and_the_bar_wave():
    """Plane strain E' = E / (1 - nu^2), nu' = nu / (1 - nu); the bar's wave
    carries sigma / (rho c) at c = sqrt(E' / rho)."""
    assert plane_moduli(1.0, 0.5, "strain") == pytest.approx((4.0 / 3.0, 1.0))
    assert plane_moduli(1.0, 0.5, "stress") == (1.0, 0.5)
    w = bar_wave(20.0, E=1e4, nu=0.0, rho=100.0)
    assert w["wave_speed"] == pytest.approx(10.0) and w["velocity"] == pytest.approx(0.02)
