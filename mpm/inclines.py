"""Closed forms of a body on a plane inclined at theta with Coulomb
friction mu between them, for the friction benchmarks
(examples/incline.py; conf/scene/incline_2d.yaml, incline_disk_2d.yaml):

* :func:`sliding`: a block's acceleration down the plane,
  a = g (sin theta - mu cos theta); from rest it stays where
  tan theta <= mu (a = 0);
* :func:`rolling`: a solid disk (moment of inertia M R^2 / 2) rolls without
  slipping at a = (2/3) g sin theta while the friction this needs,
  (1/3) M g sin theta, is within mu M g cos theta, i.e. mu >= tan(theta) / 3;
  below that threshold it slides as the block does.

Angles in degrees, g [m/s^2] the magnitude of gravity, speeds [m/s].
"""

from __future__ import annotations

import math


def sliding(theta: float, g: float, mu: float, speed: float = 0.0) -> float:
    """A block's acceleration down the plane [m/s^2]: g (sin - mu cos), or
    0 from rest (``speed`` 0) where friction holds it (tan theta <= mu)."""
    a = g * (math.sin(math.radians(theta)) - mu * math.cos(math.radians(theta)))
    return 0.0 if speed == 0.0 and a <= 0.0 else a


def rolling(theta: float, g: float, mu: float) -> float:
    """A solid disk's, from rest [m/s^2]: (2/3) g sin theta rolling
    (mu >= tan theta / 3), else sliding."""
    if mu >= math.tan(math.radians(theta)) / 3.0:
        return 2.0 / 3.0 * g * math.sin(math.radians(theta))
    return sliding(theta, g, mu, 0.0)
