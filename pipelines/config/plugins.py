"""Materials and kernels defined outside ``mpm``, for the command line.

Two ways to name one (docs/extending.md):

* a dotted path as the group's option, ``material=pkg.module.MyModel`` (a
  :class:`mpm.Material` subclass) or ``kernel=pkg.module.MY_KERNEL`` (an
  :class:`mpm.Kernel`): the module is imported from the working directory or
  ``PYTHONPATH``, the object checked and registered
  (:func:`mpm.materials.register_material`, :func:`mpm.kernels.register_kernel`)
  and offered as an option under that path, so the recorded overrides and
  choices name where it came from;
* ``MPM_PLUGINS=pkg.models[,pkg.more]``: modules imported at start-up, in
  every process of a sweep, that register their models themselves (the
  decorator): their names are then options like the built-in ones.

Everything here runs before Hydra composes (the ``material`` and ``kernel``
groups are registered from the registries, :mod:`pipelines.config.schema`)
and again in a launcher's worker process before the job is checked; a
problem is a :class:`ConfigError` naming ``material``, ``kernel`` or
``MPM_PLUGINS``: one line, exit code 2, before anything is compiled.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import os
import sys

import mpm
from mpm.kernels import register_kernel
from mpm.kernels.registry import built_in as kernel_built_in
from mpm.kernels.registry import origin as kernel_origin
from mpm.materials import register_material
from mpm.materials.registry import built_in as material_built_in
from mpm.materials.registry import origin as class_origin

from .fields import ConfigError

ENV = "MPM_PLUGINS"
GROUPS = ("material", "kernel")
# group -> dotted path given as the option -> the registered name it stands for
ALIASES: dict[str, dict[str, str]] = {group: {} for group in GROUPS}


def _first_line(text) -> str:
    return next((ln.strip() for ln in str(text).splitlines() if ln.strip()), "")


def _registry(group: str) -> dict:
    return mpm.MATERIALS if group == "material" else mpm.KERNELS


def dotted(group: str) -> str:
    """The dotted path a group's option may be, in words."""
    what = "an mpm.Material subclass (package.module.Class)" if group == "material" else \
        "an mpm.Kernel (package.module.NAME)"
    return f"the dotted path of {what}, importable from the working directory or PYTHONPATH"


def accepted(group: str) -> str:
    """What a group's option may be, in words."""
    return f"a registered {group} ({', '.join(_registry(group))}) or {dotted(group)}"


def _kind(obj) -> str:
    """What an object is, in words: ``the class X``, ``a function``, ``a Kernel``."""
    if isinstance(obj, type):
        return f"the class {obj.__name__}"
    name = type(obj).__name__
    return "a function" if callable(obj) else f"{'an' if name[:1].lower() in 'aeiou' else 'a'} {name}"


def import_module(module: str, key: str, given: str, accepted_text: str):
    """``module`` imported; anything that goes wrong is one line at ``key``
    (``given``: the value as the user wrote it)."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name and (module == e.name or module.startswith(e.name + ".")):
            raise ConfigError(key, f"{given}: no module named {e.name!r}; accepted: {accepted_text}") from None
        raise ConfigError(key, f"{given}: importing {module} failed: {_first_line(e)}; accepted: "
                               f"{accepted_text}") from None
    except Exception as e:  # noqa: BLE001 - the user's module: whatever it raises is said on one line
        raise ConfigError(key, f"{given}: importing {module} failed ({type(e).__name__}: {_first_line(e)}); "
                               f"accepted: {accepted_text}") from None


def resolve(group: str, value: str) -> str:
    """The registered name that option ``value`` of ``group`` stands for: a
    registered name as it is; a dotted path imported, checked and
    registered (then offered under the path too, :data:`ALIASES`)."""
    registry = _registry(group)
    if value in registry:
        return value
    if value in ALIASES[group]:
        return ALIASES[group][value]
    module, _, attr = value.rpartition(".")
    if not module or not attr:
        raise ConfigError(group, f"{value}: unknown option; accepted: {accepted(group)}")
    found = getattr(import_module(module, group, value, accepted(group)), attr, None)
    if found is None:
        raise ConfigError(group, f"{value}: module {module} has no {attr}; accepted: {accepted(group)}")
    try:
        if group == "material":
            if not (isinstance(found, type) and issubclass(found, mpm.Material)):
                raise ValueError(f"{_kind(found)}, not an mpm.Material subclass")
            register_material(found)
        else:
            if not isinstance(found, mpm.Kernel):
                raise ValueError(f"{_kind(found)}, not an mpm.Kernel")
            register_kernel(found)
    except ValueError as e:
        problem = str(e).split(": ", 1)[1] if str(e).startswith(f"{group} ") else str(e)
        if "; accepted: " not in problem:
            problem += f"; accepted: {accepted(group)}"
        raise ConfigError(group, f"{value}: {problem}") from None
    ALIASES[group][value] = found.name
    return found.name


def env_modules(environ=None) -> list[str]:
    """The modules ``MPM_PLUGINS`` names (comma-separated)."""
    text = (os.environ if environ is None else environ).get(ENV, "")
    return [m.strip() for m in text.split(",") if m.strip()]


def load_env(environ=None) -> list[str]:
    """Import the modules of ``MPM_PLUGINS`` (each registers its models);
    returns their names."""
    modules = env_modules(environ)
    text = ("a comma-separated list of modules, importable from the working directory or PYTHONPATH, that "
            "register materials or kernels")
    for module in modules:
        import_module(module, ENV, module, text)
    return modules


def _group_values(overrides: list[str]) -> list[tuple[str, str]]:
    """(group, option) for each ``material=`` and ``kernel=`` override, every
    option of a sweep (``-m material=a,b``) included."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    out = []
    for text in overrides:
        if text.startswith(("-", "hydra")) or text.split("=", 1)[0].lstrip("+~") not in GROUPS:
            continue
        try:
            o, = parser.parse_overrides([text])
        except Exception:  # noqa: BLE001 - Hydra says what it cannot parse
            continue
        if o.is_delete() or o.package is not None:
            continue
        value = o.value()
        values = list(getattr(value, "list", None) or []) if o.is_sweep_override() else [value]
        out += [(o.key_or_group.lstrip("+~"), v) for v in values if isinstance(v, str) and "." in v]
    return out


def prepare(overrides: list[str]) -> None:
    """Before composing: the modules of ``MPM_PLUGINS`` imported and every
    dotted path given as a ``material`` or ``kernel`` option registered.
    Call :func:`pipelines.config.schema.register` afterwards to offer them."""
    load_env()
    for group, value in _group_values(list(overrides)):
        resolve(group, value)


def _home(obj) -> str | None:
    """The plugin module (a dotted path's, or one of MPM_PLUGINS) holding
    ``obj`` as a global, if any."""
    names = [path.rpartition(".")[0] for group in GROUPS for path in ALIASES[group]] + env_modules()
    for name in dict.fromkeys(names):
        module = sys.modules.get(name)
        if module is not None and any(v is obj for v in vars(module).values()):
            return name
    return None


def _defined(scene: mpm.Scene, kernel: mpm.Kernel) -> list[tuple[str, str, str]]:
    """(label, where, module) of each material and kernel of a run that is
    not mpm's own (a copy of a built-in kernel, ``dataclasses.replace(
    mpm.QUADRATIC, ...)``, is the user's: its module is the one holding it)."""
    out = []
    for cls in dict.fromkeys(type(b.material) for b in scene.bodies):
        if not material_built_in(cls):
            out.append((f"material {cls.name}", class_origin(cls), cls.__module__))
    if not kernel_built_in(kernel):
        home = _home(kernel)
        module = home or getattr(kernel.weights, "__module__", "") or ""
        names = [k for k, v in vars(sys.modules[home]).items() if v is kernel] if home else []
        out.append((f"kernel {kernel.name}", f"{home}.{names[0]}" if names else kernel_origin(kernel), module))
    return out


def origins(scene: mpm.Scene, kernel: mpm.Kernel) -> dict[str, str]:
    """``"material <name>"`` / ``"kernel <name>"`` -> where it is defined
    (``module.Class``, ``module.NAME``), for each material and kernel of a
    run that ``mpm`` does not define (empty: all are built in)."""
    return {label: where for label, where, _ in _defined(scene, kernel)}


def _own(module) -> bool:
    """Whether ``module`` is the user's code: a file outside mpm, pipelines,
    the standard library and the installed packages."""
    path = getattr(module, "__file__", None)
    if not path or not os.path.isfile(path):
        return False
    path = os.path.realpath(path)
    files = [m.__file__ for m in (mpm, sys.modules[__name__.split(".")[0]])]
    ours = [os.path.dirname(os.path.realpath(f)) for f in files if f is not None]  # regular packages: both have one
    installed = [os.path.realpath(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix)]
    return not any(path.startswith(p + os.sep) for p in ours + installed)


def imported(name: str, limit: int = 200) -> list[str]:
    """Module ``name`` and the user's modules it uses, directly or through
    others (a global that is a module, or a class or function defined in
    one), in the order found; at most ``limit``."""
    seen, queue = [], [name]
    while queue and len(seen) < limit:
        current = queue.pop(0)
        module = sys.modules.get(current)
        if current in seen or module is None or not _own(module):
            continue
        seen.append(current)
        for value in list(vars(module).values()):
            used = value.__name__ if isinstance(value, type(sys)) else getattr(value, "__module__", None)
            if isinstance(used, str) and used not in seen:
                queue.append(used)
    return seen


def _fields(kernel: mpm.Kernel) -> str:
    """A kernel's parameters and where its factories are, as text."""
    def text(v):
        return f"{getattr(v, '__module__', '?')}.{getattr(v, '__qualname__', '?')}" if callable(v) else repr(v)
    return repr([(f.name, text(getattr(kernel, f.name))) for f in dataclasses.fields(kernel)])


def sources(scene: mpm.Scene, kernel: mpm.Kernel) -> dict[str, str]:
    """``"module <name>"`` -> SHA-256 (16 hex digits) of the source file of
    each module that defines a material or kernel of the run outside
    ``mpm``, and of the user's modules it uses (:func:`imported`), and
    ``"kernel <name>"`` -> that of a user's kernel's parameters: the run's
    config hash changes with their code."""
    out = {}
    for label, _, module in _defined(scene, kernel):
        for name in imported(module):
            path = sys.modules[name].__file__
            assert path is not None  # imported() keeps modules with a file (_own)
            with open(path, "rb") as f:
                out[f"module {name}"] = hashlib.sha256(f.read()).hexdigest()[:16]
        if label.startswith("kernel "):
            out[label] = hashlib.sha256(_fields(kernel).encode()).hexdigest()[:16]
    return out
