"""Bad input refused in one line before anything is built, and runs that
cannot advance stopped with a reason (never a hang, a traceback or a run
without metrics.json)."""

import json

import numpy as np
import pytest

from helpers import DEVICE, compose_cfg, spec_for
from pipelines.run.runner import execute
from pipelines.recording.sinks import Sink
from pipelines.config.validate import ConfigError, memory_estimate, resolve

# (overrides, the key the one-line message names, a fragment of the message)
REFUSED = [
    (["run.duration=inf"], "run.duration", "not finite"),
    (["run.dt=inf"], "run.dt", "not finite"),
    (["run.dt=nan"], "run.dt", "not finite"),
    (["material.E=nan"], "material.E", "not finite"),
    (["material.E=-inf"], "material.E", "not finite"),
    (["run.cfl=inf"], "run.cfl", "not finite"),
    (["scene.gravity=[0,inf]"], "scene.gravity[1]", "not finite"),
    (["+run.stepz=5"], "run.stepz", "unknown key"),
    (["+log.evry=3"], "log.evry", "unknown key"),
    (["+foo=1"], "foo", "unknown key"),
    (["log.recording="], "log.recording", "file name ending in .rrd"),
    (["log.recording=sub/x.rrd"], "log.recording", "without a directory"),
    (["log.recording=x.txt"], "log.recording", ".rrd"),
    (["seed=-1", "scene.jitter=0.5"], "seed", "seed >= 0"),
    (["detect.action=halt"], "detect.action", "accepted: stop, warn, off"),
    (["scene.wall_cells=40"], "scene.wall_cells", "leave no interior along axis 0"),
    (["log.fps=0"], "log.fps", "log.fps > 0"),
    (["log.fps=inf"], "log.fps", "not finite"),
    (["log.color=rainbow"], "log.color", "accepted: auto, body, dJ"),
    (["log.color=plastic_strain"], "log.color", "no plastic body"),
    (["log.color=dJ", "log.dJ=false"], "log.color", "log.dJ is false"),
    (["log.size_warning_mb=-1"], "log.size_warning_mb", "> 0"),
    (["run.device=tpu"], "run.device", "accepted: auto, cpu, cuda"),
]


@pytest.mark.parametrize("overrides, key, fragment", REFUSED, ids=lambda v: str(v)[:40])
def test_bad_input_is_refused_in_one_line_naming_the_key(overrides, key, fragment):
    with pytest.raises(ConfigError) as err:
        resolve(compose_cfg(overrides))
    text = str(err.value)
    assert err.value.key == key and fragment in text and "\n" not in text
    assert text.split("accepted: ")[-1].strip()  # never an empty list of accepted values


@pytest.mark.parametrize("override, key", [("scene.resolution=100000", "scene.resolution"),
                                           ("scene.ppc=100000", "scene.ppc")])
def test_runs_that_cannot_fit_are_refused_with_the_estimate(override, key):
    """A valid config too large for this machine's memory (24 GiB here):
    refused before sampling, with the estimate and the limit."""
    from pipelines.config.validate import check_memory

    spec = spec_for([override])
    with pytest.raises(ConfigError) as err:
        check_memory(spec)
    assert err.value.key == key and "GiB" in str(err.value) and "this machine's" in str(err.value)
    check_memory(spec_for(["scene.resolution=64"]))  # the default fits


def test_memory_estimate_bounds_what_a_build_allocates():
    """The estimate refuses what cannot fit and stays above what a small
    build actually allocates (its particle count included)."""
    import mpm

    spec = spec_for(["scene.resolution=32"])
    need, particles, nodes = memory_estimate(spec.scene, spec.kernel, "float32")
    model, state = mpm.build(spec.scene, spec.kernel, "float32", DEVICE)
    arrays = [state.x, state.v, state.C, state.F0s, state.Fsn, state.X, state.dJ, model.mass, model.volume]
    allocated = sum(a.capacity for a in arrays)
    assert particles >= model.n_particles and nodes == 33 * 33
    assert need > allocated


def test_overflowing_initial_velocity_stops_at_step_zero(tmp_path):
    """A spin of 1e30 rad/s overflows float32: the run stops before its
    first step, says why, and leaves metrics.json."""
    m = execute(spec_for(["scene=rotating_plate_2d", "scene.bodies.0.angular_velocity=1e30", "log.every=0"]),
                tmp_path, sink=Sink())
    assert m["status"] == "unstable" and m["unstable_step"] == 0 and m["unstable_criterion"] == "nonfinite"
    assert "not finite" in m["reason"]
    assert json.loads((tmp_path / "metrics.json").read_text())["status"] == "unstable"


def test_a_time_step_of_zero_stops_the_run(tmp_path):
    """At 1e19 m/s the adaptive step underflows to 0: the run stops instead
    of stepping forever at t = 0."""
    m = execute(spec_for(["scene=colliding_spheres", "scene.resolution=16", "scene.bodies.0.velocity=[1e19,0,0]",
                          "run.duration=0.01", "log.every=0"]), tmp_path, sink=Sink())
    assert m["status"] == "unstable" and m["unstable_criterion"] in ("dt_collapse", "energy", "speed", "outside")


def test_dt_min_leaves_out_the_step_that_lands_on_the_duration(tmp_path):
    m = execute(spec_for(["scene.resolution=24", "run.duration=0.0123", "log.every=0"]), tmp_path, sink=Sink())
    assert m["dt_max"] == pytest.approx(1e-3) and m["dt_min"] == pytest.approx(1e-3)  # dt_max binds
    assert m["dt"] * m["steps"] == pytest.approx(0.0123)


def test_a_failed_build_keeps_its_reason_in_metrics(tmp_path, monkeypatch):
    """An error while building is what metrics.json says (not a second error
    raised while finishing an unbuilt run)."""
    import mpm

    def broken(*args, **kwargs):
        raise MemoryError("no room")

    monkeypatch.setattr(mpm, "build", broken)
    with pytest.raises(MemoryError):
        execute(spec_for(["log.every=0"]), tmp_path, sink=Sink())
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["status"] == "failed" and m["reason"] == "MemoryError: no room"
    assert np.isfinite(m["wall_time_s"])


def test_material_override_on_a_scene_with_its_own_materials_is_said():
    from pipelines.run.__main__ import unused_overrides

    own = spec_for(["scene=rotating_plate_2d", "material.E=5"])
    notes = unused_overrides(own, ["scene=rotating_plate_2d", "material.E=5"])
    assert len(notes) == 1 and "material.E=5 has no effect" in notes[0] and "rotating_plate_2d" in notes[0]
    assert unused_overrides(spec_for(["material.E=5"]), ["material.E=5"]) == []  # the ball takes the group's
    assert unused_overrides(own, ["scene=rotating_plate_2d"]) == []


def test_a_large_recording_is_announced_before_the_run(tmp_path, capsys):
    m = execute(spec_for(["scene.resolution=24", "run.steps=3", "log.size_warning_mb=0.01"]), tmp_path, sink=Sink())
    err = capsys.readouterr().err
    assert m["status"] == "completed" and m["recording_estimate_mb"] > 0.01
    assert "warning: the recording will be about" in err and "log.size_warning_mb=0.01" in err


def test_device_auto_is_the_machine_s_device(monkeypatch):
    import warp as wp

    spec = spec_for(["run.device=auto"])
    assert spec.run.device == ("cuda" if wp.is_cuda_available() else "cpu")
    # run.device's default is the environment's MPM_DEVICE, else auto
    monkeypatch.setenv("MPM_DEVICE", "cpu")
    assert spec_for([]).run.device == "cpu"
    monkeypatch.delenv("MPM_DEVICE")
    assert spec_for([]).run.device == spec.run.device
    monkeypatch.setenv("MPM_DEVICE", "tpu")
    with pytest.raises(ConfigError, match="run.device.*accepted: auto, cpu, cuda"):
        spec_for([])
