"""MPM schemes: when the reference configuration is moved.

All schemes share one formulation (A-ULMPM paper eq. 20): stress, strain and
kernel weights are measured in a reference configuration taken at time t_s.

* EMPM (s = n): Eulerian MLS-MPM; the reference is the current configuration
  at every step, so weights are recomputed from the current positions each
  step and F^{0s} is the full deformation gradient.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class EMPM:
    """Eulerian MLS-MPM (Hu et al. 2018): the configuration is updated every step."""

    name: str = "empm"


SCHEMES = {"empm": EMPM}
