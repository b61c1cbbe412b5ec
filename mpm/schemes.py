"""MPM schemes: when each body's reference configuration is moved.

All schemes share one formulation (A-ULMPM paper eq. 20): stress, strain and
kernel weights are measured in a reference configuration taken at time t_s,
per body. What differs is the update rule, evaluated after every step from the
per-particle criterion dJ_p = |det F^sn_p - 1| (paper eq. 33):

* EMPM (s = n): update every step - Eulerian MLS-MPM (Hu et al. 2018).
* TLMPM (s = 0): never update - total Lagrangian MPM (de Vaucorbeil 2020).
* AULMPM: update a body when the fraction of its particles with
  dJ_p >= epsilon reaches eta (``criterion="paper"``: eq. 33 exactly as
  published). ``criterion="distortion"`` (the default,
  :data:`DEFAULTS`) also updates when any particle reaches dJ_p >= dJ_max or has its
  reference cell squeezed below ``stretch_min`` of its width in some
  direction (the smallest singular value s of F^sn). Why (RESULTS.md,
  "A-ULMPM on fluids"): a fluid resists no shear, and a lone
  splash particle (or a thin jet) at a wall keeps a large affine velocity
  gradient C that nothing damps; its F^sn shears at nearly constant volume,
  and one particle never makes the fraction eta, while s falls to 0 within a
  few dozen steps and its reference cell tangles (det F^sn < 0), which blows
  up a run at a fixed EMPM-sized step.
  The adaptive step avoids the blow-up by shrinking with s (a reference cell
  is s dx wide now; mpm.stepping.timestep), so under the paper's criterion the step
  collapses instead. s is also exactly the factor the step loses to the
  reference, so ``stretch_min`` is a bound on that loss: dt >= stretch_min x
  the step a fresh reference would allow, whenever the wave term binds.
  epsilon = inf turns all updates off (TLMPM), epsilon = 0 makes every step
  update (EMPM).

At an update X <- x, F^0s <- F^sn F^0s, F^sn <- I, and the cached stencil
weights are recomputed. The affine matrix C is a velocity gradient with
respect to the old reference: ``affine="keep"`` leaves it as it is (what
classic APIC/MLS-MPM does when the reference moves every step, and what makes
EMPM conserve angular momentum to round-off); ``affine="transform"``
re-expresses it in the new reference, C <- C (F^sn)^-1, which loses less
angular momentum than keep over the rare updates of A-ULMPM on solids but
amplifies C by 1/s where a reference cell is squeezed to s of its width: an
impact that crushes a particle (s -> 0) before the update blows C up, and
with the frequent updates of a fluid a lone splash particle whose affine
field squeezes its cell to half gets C doubled at every update (seen on the
droplet with the compact kernel, and on a soft ball's impact).
``affine="rotate"`` (the solids' default) turns C by the rotation R of
F^sn = R U alone, C <- C R^T: the spin crosses the update and |C| never
grows; an inverted F^sn (det <= 0) has no such R and keeps C. Keep is the
default of fluids and plastic bodies.
"""

import functools
import math
from dataclasses import dataclass
from typing import Any

import warp as wp

from .params import Names, param

AFFINE = ("keep", "transform", "rotate")
CRITERIA = ("paper", "distortion")
# A-ULMPM's parameters per kind of scene:
# solids take the paper's (0.5, 0.1) with the stretch bound 0.05: a reference
# cell squeezed to 5 % of its width updates the body before it collapses (an
# impact crushes a few particles long before 10 % of them change volume by
# half, and the step shrinks with the cell), while the isochoric shear of a
# twist or a vortex (cells down to about 0.1 of their width) keeps its
# Lagrangian reference (RESULTS.md, "Stability maps"); the paper itself names
# other criteria (the conditioning of F) as ones its framework takes. C is
# rotated over an update (never amplified; C (F^sn)^-1 grows as 1/s at a
# crushed particle). Plastic bodies the paper's (0.01, 0.01) with
# both distortion bounds at 0.5; fluids (no shear stiffness) the paper's
# (0.01, 0.01) with the stretch bound 0.9, which keeps the step within 10 % of
# EMPM's and won the aulmpm_tradeoff measurement (RESULTS.md)
DEFAULTS = {
    "solid": dict(epsilon=0.5, eta=0.1, dJ_max=math.inf, stretch_min=0.05, affine="rotate",
                  criterion="distortion"),
    "plastic": dict(epsilon=0.01, eta=0.01, dJ_max=0.5, stretch_min=0.5, affine="keep",
                    criterion="distortion"),
    "fluid": dict(epsilon=0.01, eta=0.01, dJ_max=math.inf, stretch_min=0.9, affine="keep",
                  criterion="distortion"),
}
PAPER_BOUNDS = dict(dJ_max=math.inf, stretch_min=0.0)  # eq. 33 alone: the bounds off


def scene_kind(materials) -> str:
    """"fluid" if a material has no shear stiffness, else "plastic" if one
    flows, else "solid": which defaults A-ULMPM takes."""
    materials = list(materials)
    if any(m.fluid for m in materials):
        return "fluid"
    return "plastic" if any(m.flows for m in materials) else "solid"


@dataclass
class _FixedRule:
    """A scheme whose update rule ignores the criterion; C is kept."""

    affine = "keep"

    def tracks_marks(self) -> bool:
        return False

    def problems(self) -> list[tuple[str, str]]:
        return []


@dataclass
class EMPM(_FixedRule):
    """Eulerian MLS-MPM: every body's configuration is updated every step."""

    name: str = "empm"
    """the scheme's name (the key of SCHEMES)"""

    def updates(self, marked: int, count: int, max_dJ: float, min_stretch: float) -> bool:
        return True


@dataclass
class TLMPM(_FixedRule):
    """Total Lagrangian MPM: the reference configuration is the initial one."""

    name: str = "tlmpm"
    """the scheme's name (the key of SCHEMES)"""

    def updates(self, marked: int, count: int, max_dJ: float, min_stretch: float) -> bool:
        return False


@dataclass
class AULMPM:
    """Adaptively updated Lagrangian MPM (A-ULMPM paper, eq. 33).

    Null parameters take the defaults of the scene's kind (:func:`scene_kind`,
    :data:`DEFAULTS`): with a fluid present epsilon = eta = 0.01, criterion
    distortion with stretch_min = 0.9 and no dJ_max, affine keep; with a
    plastic body the same but dJ_max = stretch_min = 0.5; solids epsilon =
    0.5, eta = 0.1 (the paper's choices), criterion distortion with
    stretch_min = 0.05 and no dJ_max, affine rotate. The paper's criterion
    ignores dJ_max and stretch_min (giving them is an error).
    ``epsilon = inf`` never updates (TLMPM), ``epsilon = 0`` always (EMPM).
    """

    name: str = "aulmpm"
    """the scheme's name (the key of SCHEMES)"""
    epsilon: float | None = param(None, "mark particles with dJ >= epsilon [-]", ge=0.0, inf=True)
    eta: float | None = param(None, "update when marked / n >= eta [-]", ge=0.0, le=1.0)
    dJ_max: float | None = param(None, "distortion: also update when any particle has dJ >= "
                                       "max(dJ_max, epsilon) [-]", gt=0.0, inf=True)
    stretch_min: float | None = param(None, "distortion: also update when a reference cell is "
                                            "squeezed below this fraction of its width [-]", ge=0.0, lt=1.0)
    affine: str | None = param(None, "C over an update: transform (re-expressed in the new reference), "
                                     "rotate (by F^sn's rotation only: never amplified) or keep; null: the "
                                     "scene kind's default", choices=AFFINE)
    criterion: str | None = param(None, "paper (eq. 33 as published: epsilon, eta only) or distortion "
                                        "(also dJ_max, stretch_min); null: the scene kind's default",
                                  choices=CRITERIA)

    def resolved(self, kind: str) -> "AULMPM":
        """Defaults filled in for a scene of ``kind`` (:func:`scene_kind`)."""
        defaults = dict(DEFAULTS[kind])
        if (self.criterion or defaults["criterion"]) == "paper":
            defaults.update(PAPER_BOUNDS)
        given = {k: getattr(self, k) for k in defaults}
        values: dict[str, Any] = {k: defaults[k] if v is None else v for k, v in given.items()}
        return AULMPM(name=self.name, **values)

    def problems(self) -> list[tuple[str, str]]:
        """(key, message) for inconsistent settings."""
        if self.criterion == "paper" and (self.dJ_max is not None or self.stretch_min is not None):
            key = "dJ_max" if self.dJ_max is not None else "stretch_min"
            return [(key, "is not part of criterion 'paper' (eq. 33: epsilon and eta only); "
                          "use criterion=distortion or leave it null")]
        return []

    def updates(self, marked: int, count: int, max_dJ: float, min_stretch: float) -> bool:
        epsilon, eta, dJ_max, stretch_min = self.epsilon, self.eta, self.dJ_max, self.stretch_min
        assert epsilon is not None and eta is not None and dJ_max is not None and stretch_min is not None, \
            "resolved() fills every bound"
        if math.isinf(epsilon):
            return False
        if marked >= eta * count:
            return True
        return self.criterion == "distortion" and (max_dJ >= max(dJ_max, epsilon) or min_stretch < stretch_min)

    def tracks_marks(self) -> bool:
        assert self.epsilon is not None, "resolved() fills epsilon"
        return not math.isinf(self.epsilon)


SCHEMES = Names("scheme", {"empm": EMPM, "tlmpm": TLMPM, "aulmpm": AULMPM})
"""name -> scheme class: Eulerian (every step), total Lagrangian (never) and
adaptively updated Lagrangian (when the criterion says) reference updates"""


@wp.struct
class RuleParams:
    """A-ULMPM's criterion on the device (:func:`make_update_rule`)."""

    epsilon: wp.float64
    eta: wp.float64
    dJ_max: wp.float64
    stretch_min: wp.float64


def rule_params(scheme) -> RuleParams:  # pyright: ignore[reportGeneralTypeIssues]  (a wp.struct)
    p = RuleParams()
    p.epsilon, p.eta = float(getattr(scheme, "epsilon", 0.0) or 0.0), float(getattr(scheme, "eta", 0.0) or 0.0)
    p.dJ_max, p.stretch_min = (float(getattr(scheme, "dJ_max", 0.0) or 0.0),
                               float(getattr(scheme, "stretch_min", 0.0) or 0.0))
    return p


def rule_kind(scheme) -> str:
    """``always`` (EMPM), ``never`` (TLMPM, or A-ULMPM with epsilon = inf),
    or A-ULMPM's criterion (``paper`` or ``distortion``)."""
    if scheme.name == "empm":
        return "always"
    if scheme.name == "tlmpm" or math.isinf(scheme.epsilon):
        return "never"
    return scheme.criterion


@functools.cache
def make_update_rule(kind: str):
    """``updates(marked, count, max_dJ, min_stretch, params) -> bool`` on the
    device, the scheme's rule (``updates`` above) for :func:`rule_kind`
    ``kind``, in float64 with the host's comparisons."""
    f64 = wp.float64

    @wp.func
    def updates(marked: f64, count: f64, max_dJ: f64, min_stretch: f64, params: RuleParams):  # pyright: ignore[reportGeneralTypeIssues]
        fire = bool(False)
        if wp.static(kind == "always"):
            fire = True
        elif wp.static(kind != "never"):
            fire = marked >= params.eta * count
            if wp.static(kind == "distortion"):
                bound = params.dJ_max
                if params.epsilon > bound:  # max(dJ_max, epsilon)
                    bound = params.epsilon
                fire = fire or max_dJ >= bound or min_stretch < params.stretch_min
        return fire

    return updates
