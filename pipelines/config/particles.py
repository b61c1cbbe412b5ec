"""The particles a validated run will have, checked before anything is
compiled or allocated: the bodies are sampled by :func:`mpm.model.sample_bodies`, as
:func:`mpm.build` samples them, so that a body that holds no
particle, a kinematic region or a load that selects none is refused in one
line naming it, its bounds and the domain's; bodies that overlap at the
start are said in a warning with the overlap's size."""

from __future__ import annotations

import numpy as np

import mpm
from mpm.loads import LoadError, resolve
from mpm.meshes import MeshShape
from mpm.model import sample_bodies

from .fields import ConfigError


def _box(lo, hi) -> str:
    return " x ".join(f"[{a:.4g}, {b:.4g}]" for a, b in zip(lo, hi))


def _bounds(shape) -> str:
    return _box(*(np.asarray(v, float) for v in shape.bounds()))


def _meshes(shape) -> list[str]:
    """The mesh files a shape reads."""
    if isinstance(shape, MeshShape):
        return [shape.source]
    inner = [shape.shape] if isinstance(shape, mpm.scene.Rotated) else list(getattr(shape, "parts", ()))
    return [m for s in inner for m in _meshes(s)]


def check_particles(scene: mpm.Scene, seed: int, key: str = "scene", samples: list | None = None) -> list[str]:
    """Raise :class:`ConfigError` for a body without particles, a region or a
    load that selects none; return warnings (bodies overlapping at the start).
    ``samples``: the bodies already sampled for this scene and seed."""
    d, dxp = scene.dim, scene.particle_dx
    domain = _box([0.0] * d, scene.domain)
    names = [b.name or f"body{i}" for i, b in enumerate(scene.bodies)]
    samples = sample_bodies(scene, seed) if samples is None else samples
    xs = [s.x for s in samples]
    for i, (b, x) in enumerate(zip(scene.bodies, xs)):
        if len(x):
            continue
        ppc = b.ppc or scene.ppc
        files = _meshes(b.shape)
        what = f" (the mesh {', '.join(files)})" if files else ""
        spacing = (dxp ** d / ppc) ** (1.0 / d)
        raise ConfigError(f"{key}.bodies[{i}].shape",
                          f"body '{names[i]}'{what} holds no particle: it spans {_bounds(b.shape)}, the particles "
                          f"are about {spacing:.4g} m apart (ppc {ppc}, domain {domain}); accepted: a shape larger "
                          f"than the particle spacing (or a finer scene.resolution)")
    for r, reg in enumerate(scene.regions):
        x = xs[reg.body]
        if not reg.select.contains(x).any():
            lo, hi = x.min(axis=0), x.max(axis=0)
            raise ConfigError(f"{key}.regions[{r}].select",
                              f"region '{reg.name or f'region{r}'}' selects no particle of body '{names[reg.body]}': "
                              f"it spans {_bounds(reg.select)}, the body's particles {_box(lo, hi)} (domain {domain});"
                              f" accepted: a selection that overlaps the body")
    if scene.loads:
        vols = [np.full(len(s.x), s.volume) for s in samples]
        ids = [np.full(len(s.x), i, np.int32) for i, s in enumerate(samples)]
        counts = [len(x) for x in xs]
        ranges = [(int(s), n) for s, n in zip(np.cumsum([0] + counts[:-1]), counts)]
        spacing = [(dxp ** d / (b.ppc or scene.ppc)) ** (1.0 / d) for b in scene.bodies]
        try:
            resolve(scene.loads, np.concatenate(xs), np.concatenate(vols), np.concatenate(ids), ranges, spacing,
                    scene.dx, names)
        except LoadError as e:
            if e.key == "at":  # a point load off its body
                raise ConfigError(f"{key}.loads[{e.index}].at", e.message) from None
            load = scene.loads[e.index]
            which = list(range(len(xs))) if load.body is None else [load.body]
            x = np.concatenate([xs[b] for b in which])
            whose = "any body" if load.body is None else f"body '{names[load.body]}'"
            span = f"it spans {_bounds(load.select)}, " if load.select is not None else ""
            raise ConfigError(f"{key}.loads[{e.index}].{e.key}",
                              f"load '{load.name or f'load{e.index}'}' selects no particle of {whose}: {span}the "
                              f"particles span {_box(x.min(axis=0), x.max(axis=0))} (domain {domain}); accepted: "
                              f"a selection that overlaps the body") from None
    return overlaps(scene, xs, names, key)


def overlaps(scene: mpm.Scene, xs: list[np.ndarray], names: list[str], key: str = "scene") -> list[str]:
    """A warning per pair of bodies whose particles start inside the other's shape."""
    d, dxp = scene.dim, scene.particle_dx
    notes = []
    boxes = [tuple(np.asarray(v, float) for v in b.shape.bounds()) for b in scene.bodies]
    for i, bi in enumerate(scene.bodies):
        if bi.deformation is not None:
            continue
        for j, bj in enumerate(scene.bodies):
            if j == i or (j < i and scene.bodies[j].deformation is None) or not len(xs[j]):
                continue
            lo = np.maximum(boxes[i][0], xs[j].min(axis=0))
            hi = np.minimum(boxes[i][1], xs[j].max(axis=0))
            if np.any(lo > hi):
                continue
            n = int(bi.shape.contains(xs[j]).sum())
            if n:
                volume = n * dxp ** d / (bj.ppc or scene.ppc)
                unit = "m^2" if d == 2 else "m^3"
                notes.append(f"{key}.bodies[{i}] ('{names[i]}') and {key}.bodies[{j}] ('{names[j]}') overlap at "
                             f"the start: {n} particles of '{names[j]}' (about {volume:.3g} {unit}) lie inside "
                             f"'{names[i]}'; move or shrink one of them (both would hold that volume's mass)")
    return notes
