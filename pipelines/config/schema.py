"""The configuration Hydra composes: the root :class:`Config` and every
group's options, registered with Hydra's ConfigStore so that a misspelt key
or a mistyped value fails at composition.

Each group is defined once (:mod:`pipelines.config.fields` says how and
why): ``material``, ``scheme`` and ``integrator`` by the solver's classes,
one ConfigStore node per option (:mod:`pipelines.config.physics`);
``kernel`` by :class:`KernelConfig`, one node per kernel of
:data:`mpm.KERNELS` (models and kernels registered from outside ``mpm``
included, and a dotted path given as the option:
:mod:`pipelines.config.plugins`); ``scene`` by :class:`SceneConfig`, whose
options are the files of ``conf/scene/`` (values only); ``run``, ``log``,
``detect`` and ``stability_map`` are settings of the root. The files in
``conf/`` hold values: the defaults list, the scenes, the scales and the
experiments.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, OmegaConf

import mpm

from .fields import setting
from .physics import GROUPS
from .plugins import ALIASES
from .scene import SceneConfig
from .settings import DEVICES, PRECISIONS, KernelConfig, LogSettings, MapSpec, RunSettings

__all__ = ["Config", "DEVICES", "PRECISIONS", "options", "register"]
CONF = Path(__file__).resolve().parents[2] / "conf"


@dataclass
class Config:
    """A run: the options of the groups and the settings."""

    scheme: Any = setting(MISSING, "when a body's reference configuration moves (mpm.schemes)")
    integrator: Any = setting(MISSING, "forward or backward Euler on the grid velocities (mpm.integrators)")
    kernel: KernelConfig = setting(MISSING, "interpolation kernel and transfer")
    material: Any = setting(MISSING, "the material of every body that does not bring its own (mpm.materials)")
    scene: SceneConfig = setting(MISSING, "the domain, bodies, regions and colliders (conf/scene)")
    run: RunSettings = setting(RunSettings(), "how long and how to step")
    log: LogSettings = setting(LogSettings(), "what goes into the recording")
    detect: mpm.Detection = setting(mpm.Detection(), "blow-up detection (mpm.stepping.detection)")
    seed: int = setting(0, "seeds the random particle sampling and random shape rotations", ge=0)
    scale: Any = setting(None, "sizes of the named experiments (conf/scale), read by conf/experiment")
    stability_map: Optional[MapSpec] = setting(None, "the job is a stability map (pipelines.run.stability_map)")
    expected: Optional[str] = setting(None, "the outcome a case of the extreme suite should have (conf/extreme)")


def option_nodes() -> dict[str, dict[str, Any]]:
    """group -> option -> the ConfigStore node of the groups defined in code."""
    nodes = {group: {name: cls() for name, cls in family.variants.items()} for group, family in GROUPS.items()}
    nodes["kernel"] = {name: KernelConfig(name=name) for name in mpm.KERNELS}
    for group, aliases in ALIASES.items():  # a dotted path given as the option (pipelines.config.plugins)
        nodes[group].update({path: nodes[group][name] for path, name in aliases.items()})
    return nodes


def options(group: str) -> list[str]:
    """The options of a group, sorted: its nodes and its files in ``conf/``."""
    files = [p.stem for p in (CONF / group).glob("*.yaml")] if (CONF / group).is_dir() else []
    return sorted(set(option_nodes().get(group, {})) | set(files))


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity: what a container
    or ``taskset`` leaves it), the sweep launcher's default worker count
    (``hydra.launcher.n_jobs: ${cores:}``): a Warp CPU run steps on one core."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def register() -> None:
    """Register the root schema, every option defined in code and the
    ``${cores:}`` resolver."""
    OmegaConf.register_new_resolver("cores", usable_cores, replace=True)
    cs = ConfigStore.instance()
    cs.store(name="config_schema", node=Config)
    for group, nodes in option_nodes().items():
        for name, node in nodes.items():
            cs.store(group=group, name=name, node=node)


def group_fields() -> dict[str, list[dataclasses.Field]]:
    """Every dataclass that defines a part of the configuration -> its fields
    (for the documentation and the tests)."""
    from .colliders import COLLIDERS
    from .scene import SOLUTION, BodyConfig, LoadConfig, RegionConfig
    from .shapes import SHAPES

    classes = [Config, RunSettings, LogSettings, KernelConfig, MapSpec, SceneConfig, BodyConfig, RegionConfig,
               LoadConfig,
               mpm.Detection]
    for family in (*GROUPS.values(), SHAPES, COLLIDERS, SOLUTION):
        classes += list(family.variants.values())
    return {cls: list(dataclasses.fields(cls)) for cls in classes}
