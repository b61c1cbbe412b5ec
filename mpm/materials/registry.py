"""The registry of material models: :data:`MATERIALS` maps a model's name to
its class, and :func:`register_material` adds a class defined anywhere (a
researcher's own file) after checking it.

A registered model is an option like the built-in ones: ``mpm.Body(shape,
MyModel(...))`` needs no registration, but the ``material`` config group
(``material=<name>``) and every lookup by name (``MATERIALS[name]``, a body's
inline ``{model: <name>}``) do. The solver compiles per class (its factories
are called with the run's :class:`mpm.types.Types`), so a model compiles only
its own code, and only in a run that uses it.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Callable

from ..factories import probe
from ..params import Names
from ..types import N_MATERIAL_PARAMS
from .base import Material
from .plastic import Plastic

NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # a name usable as a config option and a key

MATERIALS: dict[str, type[Material]] = Names("material")
"""model name -> material class: the built-in ones and those registered (the ``material`` config
group's options)"""
BUILT_IN: dict[str, type[Material]] = {}
"""model name -> class: mpm's own (a registered class may not take their names)"""


RETURNS = {"stress_energy": (2, "P, psi"), "principal": (3, "P_hat, psi, H"), "project": (1, "F"),
           "flow": (2, "sigma_E, history"), "elasticity": (2, "P_hat, psi"), "elasticity_hessian": (1, "H"),
           "stiffening": (1, "factor")}
"""what each factory's Warp function returns: how many values, and which (mpm.materials.base, .plastic)"""


def origin(obj) -> str:
    """Where a class or function is defined: ``module.QualifiedName``."""
    return f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', type(obj).__name__)}"


def _said(e: Exception) -> str:
    """An exception in one line: its type and the first line of its message."""
    first = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), "")
    return f"{type(e).__name__}: {first}" if first else type(e).__name__


def _factories(cls) -> tuple[list[str], list[str]]:
    """(the factories ``cls`` has, those it lacks or gives as something not callable)."""
    if cls.plastic:
        required, optional = ("flow", "elasticity", "elasticity_hessian"), ("stiffening",)
    else:
        required, optional = ("stress_energy", "principal"), ("project",)
    bad = [n for n in required if not callable(getattr(cls, n, None))]
    bad += [n for n in optional if getattr(cls, n, None) is not None and not callable(getattr(cls, n))]
    given = [n for n in (*required, *optional) if n not in bad and getattr(cls, n, None) is not None]
    return given, bad


def material_problem(cls, factories: bool = True) -> str | None:
    """What keeps ``cls`` from being a material model (None: nothing): a
    dataclass subclass of :class:`Material` with a name usable as an option,
    the factories of its kind (elastic or fluid: ``stress_energy`` and
    ``principal``; plastic, a :class:`Plastic`: ``flow``, ``elasticity`` and
    ``elasticity_hessian``), defaults for every field, at most
    ``N_MATERIAL_PARAMS`` packed parameters and a finite positive wave speed;
    ``factories``: each factory, called for 2D float32, gives a Warp function."""
    if not (isinstance(cls, type) and issubclass(cls, Material)):
        return f"not a subclass of mpm.Material ({type(cls).__name__ if not isinstance(cls, type) else 'a class'})"
    if not dataclasses.is_dataclass(cls):
        return "not a dataclass; accepted: a class decorated with @dataclasses.dataclass"
    fields = {f.name for f in dataclasses.fields(cls)}
    loose = [k for k, tp in vars(cls).get("__annotations__", {}).items()
             if k not in fields and "ClassVar" not in str(tp)]
    if loose:
        return f"{', '.join(loose)}: not dataclass fields; accepted: the class decorated with @dataclasses.dataclass"
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not NAME.fullmatch(name):
        return f"name {name!r}; accepted: a class attribute name, letters, digits and _ (e.g. name = \"my_model\")"
    if cls.plastic and not issubclass(cls, Plastic):
        return "plastic = True in a class that is not an mpm.materials.Plastic; accepted: a Plastic subclass"
    given, missing = _factories(cls)
    if missing:
        return (f"{', '.join(missing)} missing or not callable; accepted: factories types -> Warp function "
                "(mpm.materials.base, mpm.materials.plastic)")
    if factories:
        problem = probe(cls, [(n, (), RETURNS[n]) for n in given])
        if problem:
            return problem
    try:
        obj = cls()
    except Exception as e:  # noqa: BLE001 - said in the message
        return f"cannot be made from its defaults ({_said(e)}); accepted: a default for every field"
    try:
        params = tuple(float(v) for v in obj.packed())
    except NotImplementedError:
        return "packed() is not defined; accepted: a method returning the per-body parameter vector"
    except Exception as e:  # noqa: BLE001 - said in the message
        return f"packed() fails ({_said(e)})"
    if len(params) > N_MATERIAL_PARAMS:
        return f"packed() gives {len(params)} values; accepted: at most N_MATERIAL_PARAMS = {N_MATERIAL_PARAMS}"
    vp = cls.viscosity_param
    if vp is not None and not (isinstance(vp, int) and 0 <= vp < len(params)):
        return f"viscosity_param {vp!r}; accepted: None or an index into packed() (0 to {len(params) - 1})"
    try:
        c = float(obj.wave_speed())
    except NotImplementedError:
        return "wave_speed() is not defined; accepted: a method returning the wave speed [m/s] (the time step)"
    except Exception as e:  # noqa: BLE001 - said in the message
        return f"wave_speed() fails ({_said(e)})"
    if not (math.isfinite(c) and c > 0.0):
        return f"wave_speed() = {c}; accepted: a finite speed > 0 [m/s]"
    return None


def register_material(cls: type[Material] | None = None) -> type[Material] | Callable:
    """Add material class ``cls`` to :data:`MATERIALS` under ``cls.name``
    and return it (usable as a class decorator, above ``@dataclass``).
    Registering the same class again does nothing; a class defined at the
    same place (a reloaded module) replaces its earlier self. Raises a
    one-line ValueError naming the class and what is wrong: see
    :func:`material_problem`, or a name another class holds."""
    if cls is None:  # @register_material()
        return register_material
    return _add(cls, factories=True)


def _add(cls, factories: bool):
    """:func:`register_material`; the built-in models skip calling their
    factories (done by every run that uses them)."""
    problem = material_problem(cls, factories)
    where = origin(cls) if isinstance(cls, type) else repr(cls)
    if problem is not None:
        raise ValueError(f"material {where}: {problem}")
    held = MATERIALS.get(cls.name)
    if held is not None and held is not cls and (cls.name in BUILT_IN or origin(held) != where):
        raise ValueError(f"material {where}: name {cls.name!r} is taken by {origin(held)}; accepted: a name "
                         f"not in {', '.join(MATERIALS)}")
    MATERIALS[cls.name] = cls
    if not factories:
        BUILT_IN[cls.name] = cls
    return cls


def built_in(cls) -> bool:
    """Whether material class ``cls`` is one of mpm's own (the class itself:
    a subclass defined elsewhere is the user's)."""
    return BUILT_IN.get(getattr(cls, "name", "")) is cls
