"""Reference solutions of loaded beams, for the external-load benchmarks
(mpm.loads; conf/scene/cantilever_2d.yaml and the bar of tests/mpm/test_loads.py).

* :func:`cantilever_tip`: a cantilever of length L, height H and unit depth
  under a tip shear force P [N per metre of depth], small deflection:
      Euler-Bernoulli   delta = P L^3 / (3 E' I),   I = H^3 / 12,
      2D elasticity     delta = P L^3 / (3 E' I) + (4 + 5 nu') P L / (2 E' H)
  (Timoshenko & Goodier, Theory of Elasticity, 3rd ed., 1970, section 21,
  the end clamped at the centroid), with E' = E / (1 - nu^2) and
  nu' = nu / (1 - nu) in plane strain (the 2D scenes here), E and nu in
  plane stress;
* :func:`elastica_tip`: the inextensible elastica of a cantilever under a
  dead tip load (Bisshopp & Drucker 1945, Q. Appl. Math. 3, 272-275), by
  shooting: with the arc length s / L and the slope theta,
      theta'' = -alpha cos(theta),  theta(0) = 0,  theta'(1) = 0,
      alpha = P L^2 / (E' I),
  and the tip's deflection and shortening over L, int sin(theta) ds and
  1 - int cos(theta) ds;
* :func:`bar_wave`: a bar at rest under an end traction applied suddenly
  (the step's wave): particle velocity sigma / (rho c) behind the front,
  which travels at c = sqrt(E' / rho); the loaded end moves at that speed
  until the wave returns from the far end at t = 2 L / c.
"""

from __future__ import annotations

import math

import numpy as np


def plane_moduli(E: float, nu: float, plane: str = "strain") -> tuple[float, float]:
    """(E', nu') of a 2D model: plane strain E / (1 - nu^2), nu / (1 - nu); plane stress E, nu."""
    if plane == "stress":
        return E, nu
    return E / (1.0 - nu * nu), nu / (1.0 - nu)


def cantilever_tip(P: float, L: float, H: float, E: float, nu: float, plane: str = "strain") -> dict:
    """The small tip deflection [m] of a cantilever under a tip force P
    [N/m]: Euler-Bernoulli's and 2D elasticity's (with shear)."""
    Ep, nup = plane_moduli(E, nu, plane)
    bending = P * L**3 / (3.0 * Ep * H**3 / 12.0)
    return {"euler_bernoulli": bending, "elasticity": bending + (4.0 + 5.0 * nup) * P * L / (2.0 * Ep * H)}


def _integrate(alpha: float, kappa0: float, n: int):
    """RK4 over s in [0, 1] of (theta, theta', x, y) with theta'' = -alpha cos theta."""
    def f(y):
        th, k = y[0], y[1]
        return np.array([k, -alpha * math.cos(th), math.cos(th), math.sin(th)])

    y = np.array([0.0, kappa0, 0.0, 0.0])
    h = 1.0 / n
    for _ in range(n):
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        y = y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


def elastica_tip(alpha: float, n: int = 2000) -> tuple[float, float]:
    """(deflection / L, shortening / L) of the tip of a cantilever elastica
    under a dead tip load, alpha = P L^2 / (E' I) > 0 (bisection on the
    root curvature theta'(0) in (0, alpha], where theta'(1) changes sign)."""
    lo, hi = 0.0, alpha  # theta'(1) = theta'(0) - alpha int cos: > 0 at hi, < 0 at lo
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _integrate(alpha, mid, n)[1] > 0.0:
            hi = mid
        else:
            lo = mid
    th, k, x, y = _integrate(alpha, 0.5 * (lo + hi), n)
    return float(y), float(1.0 - x)


def bar_wave(traction: float, E: float, nu: float, rho: float, plane: str = "strain") -> dict:
    """A suddenly applied end traction sigma [Pa]: wave speed c [m/s], the
    particle velocity behind the front [m/s] and the strain it carries."""
    Ep, _ = plane_moduli(E, nu, plane)
    # a bar of a 2D model free at its sides: uniaxial stress, modulus E'
    c = math.sqrt(Ep / rho)
    return {"wave_speed": c, "velocity": traction / (rho * c), "strain": traction / Ep}
