"""Hertz contact of an elastic sphere (3D) or cylinder (2D, plane strain)
pressed between two flat plates, for the contact benchmarks
(examples/hertz.py).

Each plate touches the body at one point (a line in 2D); the contact
modulus of a body (E, nu) against a plate (E2, nu2; rigid: E2 = inf) is
    1 / E* = (1 - nu^2) / E + (1 - nu2^2) / E2.
The approach of the two plates is the sum of what each contact takes.

* Sphere of radius R under a force F [N] (Hertz 1882; K. L. Johnson,
  Contact Mechanics, 1985, ch. 4): the approach of distant points
      delta = (3 F / (4 E* sqrt(R)))^(2/3),   F = (4/3) E* sqrt(R) delta^(3/2),
  contact radius a = sqrt(R delta).
* Cylinder of radius R under a load P per unit length [N/m]: the contact
  half-width (Johnson, ch. 4)
      b = sqrt(4 P R / (pi E*)),
  and the approach of the cylinder's axis to the plate
      delta = P / (pi E*) (2 ln(4 R / b) - 1),
  so that between two rigid plates the diameter shortens by
  2 P (1 - nu^2) / (pi E) (2 ln(4R/b) - 1) (as in Johnson, ch. 5). A line
  contact has no approach of distant points (the half-plane's displacement
  grows as ln r); this one follows from the stress on the loaded diameter:
  each contact's semi-elliptic pressure gives, at depth z below it on the
  axis, sigma_z = -p0 b / sqrt(b^2 + z^2) and
  sigma_x = -(p0 / b) ((b^2 + 2 z^2) / sqrt(b^2 + z^2) - 2 z), p0 = 2 P / (pi b),
  and the finite disk adds a uniform tension P / (pi R) in both directions
  (the term that frees its rim in the point-load solution). Integrated over
  the diameter (b << R), int sigma_y = -(4 P / pi) ln(4R/b) + 2 P / pi and
  int sigma_x = 0, and the plane-strain shortening -int eps_y is the
  formula above.

Both hold while the contact is small against the body (a, b << R) and the
strains small (p0 << E).
"""

from __future__ import annotations

import math

RIGID = math.inf


def contact_modulus(E: float, nu: float, E2: float = RIGID, nu2: float = 0.0) -> float:
    """E* [Pa] of a body (E, nu) against another (E2, nu2; rigid: inf)."""
    return 1.0 / ((1.0 - nu * nu) / E + (0.0 if math.isinf(E2) else (1.0 - nu2 * nu2) / E2))


def sphere_load(delta: float, R: float, Es: float) -> float:
    """The force [N] pressing a sphere of radius R [m] on a plate by
    ``delta`` [m]: (4/3) E* sqrt(R) delta^(3/2)."""
    return 4.0 / 3.0 * Es * math.sqrt(R) * max(delta, 0.0) ** 1.5


def sphere_approach(F: float, R: float, Es: float) -> float:
    """The approach [m] under a force F [N]: (3 F / (4 E* sqrt(R)))^(2/3)."""
    return (3.0 * max(F, 0.0) / (4.0 * Es * math.sqrt(R))) ** (2.0 / 3.0)


def cylinder_half_width(P: float, R: float, Es: float) -> float:
    """The contact half-width b [m] under a load P [N/m]: sqrt(4 P R / (pi E*))."""
    return math.sqrt(4.0 * max(P, 0.0) * R / (math.pi * Es))


def cylinder_approach(P: float, R: float, Es: float) -> float:
    """The approach [m] of a cylinder's axis to the plate under a load P
    [N/m]: P / (pi E*) (2 ln(4 R / b) - 1)."""
    if P <= 0.0:
        return 0.0
    b = cylinder_half_width(P, R, Es)
    return P / (math.pi * Es) * (2.0 * math.log(4.0 * R / b) - 1.0)


def plates_load(approach: float, R: float, dim: int, Es_top: float, Es_bottom: float) -> float:
    """The load [N in 3D, N/m in 2D] at which two plates whose contacts
    have the moduli ``Es_top`` and ``Es_bottom`` [Pa] have approached by
    ``approach`` [m]: the root of delta_top(F) + delta_bottom(F) = approach
    (increasing in F while b < 4 R / e), by bisection in log F."""
    if approach <= 0.0:
        return 0.0
    each = sphere_approach if dim == 3 else cylinder_approach

    def total(F):
        return each(F, R, Es_top) + each(F, R, Es_bottom)
    lo, hi = 1e-12 * Es_top * R ** (dim - 1), 1e-1 * Es_top * R ** (dim - 1)
    if total(hi) < approach:
        raise ValueError(f"plates_load: approach {approach:g} m is beyond the small-contact range of R = {R:g} m")
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if total(mid) < approach else (lo, mid)
    return math.sqrt(lo * hi)
