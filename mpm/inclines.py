"""Closed forms of a body on a plane inclined at theta with Coulomb
friction mu between them, for the friction benchmarks
(examples/incline.py; conf/scene/incline_2d.yaml, incline_disk_2d.yaml):

* :func:`sliding`: a block's acceleration down the plane,
  a = g (sin theta - mu cos theta); from rest it stays where
  tan theta <= mu (a = 0);
* :func:`rolling`: a solid disk (moment of inertia k M R^2, k = 1/2) rolls
  without slipping at a = g sin theta / (1 + k) = (2/3) g sin theta while
  the friction this needs, k M a = (1/3) M g sin theta, is within
  mu M g cos theta, i.e. mu >= tan(theta) / 3; below that threshold it
  slides as the block does. A solid sphere (``shape="sphere"``, k = 2/5)
  rolls at (5/7) g sin theta where mu >= (2/7) tan theta.

Angles in degrees, g [m/s^2] the magnitude of gravity, speeds [m/s].
"""

from __future__ import annotations

import math


def sliding(theta: float, g: float, mu: float, speed: float = 0.0) -> float:
    """A block's acceleration down the plane [m/s^2]: g (sin - mu cos), or
    0 from rest (``speed`` 0) where friction holds it (tan theta <= mu)."""
    a = g * (math.sin(math.radians(theta)) - mu * math.cos(math.radians(theta)))
    return 0.0 if speed == 0.0 and a <= 0.0 else a


INERTIA = {"disk": 0.5, "sphere": 0.4}
"""a solid body's moment of inertia about its centre over M R^2 [-]"""


def rolling(theta: float, g: float, mu: float, shape: str = "disk") -> float:
    """A solid disk's or sphere's, from rest [m/s^2]: g sin theta / (1 + k)
    rolling (mu >= k tan theta / (1 + k)), else sliding."""
    k = INERTIA[shape]
    if mu >= k / (1.0 + k) * math.tan(math.radians(theta)):
        return g * math.sin(math.radians(theta)) / (1.0 + k)
    return sliding(theta, g, mu, 0.0)
