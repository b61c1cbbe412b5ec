"""A stand-in for Genesis in the bench's tests: the calls
pipelines/bench/genesis_peer.py makes, each recording its arguments in the
JSON file ``STUB_GENESIS_LOG``; a step does nothing. The particle count is
the sphere's volume over the particle size cubed. ``STUB_GENESIS_FAIL``: a
step raises, as a broken install would."""

import json
import math
import os
import types

__version__ = "stub"
cpu = "cpu"
_log = {}


def _record(key, **kwargs):
    _log[key] = kwargs
    with open(os.environ["STUB_GENESIS_LOG"], "w") as f:
        json.dump(_log, f)
    return types.SimpleNamespace(**kwargs)


def init(**kwargs):
    _record("init", **kwargs, threads=os.environ.get("QD_NUM_THREADS"))


options = types.SimpleNamespace(SimOptions=lambda **k: _record("sim", **k),
                                MPMOptions=lambda **k: _record("mpm", **k))
materials = types.SimpleNamespace(MPM=types.SimpleNamespace(Elastic=lambda **k: _record("material", **k)))
morphs = types.SimpleNamespace(Sphere=lambda **k: _record("sphere", **k))


class Scene:
    def __init__(self, sim_options, mpm_options, show_viewer):
        self.mpm = mpm_options

    def add_entity(self, material, morph):
        n = (4 / 3) * math.pi * morph.radius ** 3 / self.mpm.particle_size ** 3
        return types.SimpleNamespace(n_particles=round(n))

    def build(self):
        pass

    def step(self):
        if os.environ.get("STUB_GENESIS_FAIL"):
            raise RuntimeError("stub genesis: the step failed")
