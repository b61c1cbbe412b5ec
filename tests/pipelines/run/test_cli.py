"""The command line: one-line configuration errors with exit code 2, clean
stops on instability, on Ctrl-C and on SIGTERM (a checkpoint first), each
leaving a readable recording and metrics.json."""

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import ROOT, run_cli

RERUN = Path(sys.executable).parent / "rerun"

BAD_INPUTS = [
    (["material.Ee=1"], "material.Ee: unknown key; accepted: model, rho, E, nu"),
    (["material.nu=0.5"], "material.nu: 0.5 out of range; accepted: -1.0 < nu < 0.5"),
    (["material.E=0"], "material.E: 0.0 out of range; accepted: 0.0 < E"),
    (["material.rho=-1"], "material.rho: -1.0 out of range; accepted: 0.0 < rho"),
    (["material=fluid", "material.gamma=1"], "material.gamma: 1.0 out of range; accepted: 1.0 < gamma"),
    (["scene=nope"], "scene=nope: unknown option; accepted: ball_in_cylinder, bowl_fsi,"),
    (["scene=ball_in_cylinder", "scheme=tlmpm"],
     "scene.contact: 'shared' (one grid for all bodies) needs scheme=empm"),
    (["scheme=nope"], "scheme=nope: unknown option; accepted: aulmpm, empm, tlmpm"),
    (["scheme=aulmpm", "scheme.eta=2"], "scheme.eta: 2.0 out of range; accepted: 0.0 <= eta <= 1.0"),
    (["scheme=aulmpm", "scheme.epsilon=-1"], "scheme.epsilon: -1.0 out of range; accepted: 0.0 <= epsilon"),
    (["scheme=aulmpm", "scheme.affine=twist"], "scheme.affine: 'twist' unknown; accepted: keep, transform, rotate"),
    (["scheme=tlmpm", "scheme.epsilon=1"], "scheme.epsilon: not a parameter of tlmpm (its keys: name); accepted: "
                                           "choose the option that takes epsilon with the group, scheme=aulmpm"),
    # an option of the implicit integrator, with the explicit one chosen (by default, or by key)
    (["integrator.name=implicit", "integrator.newton_max=5"],
     "integrator.newton_max: not a parameter of explicit (its keys: name); accepted: choose the option that takes "
     "newton_max with the group, integrator=implicit (its keys: name, newton_max,"),
    (["material.model=fluid"], "material.model: fluid set by key keeps E, nu of the material it replaces"),
    # a compound given whole runs; its wrong forms name the shape's type and keys
    (["scene.bodies.0.shape={type: compound}"], "scene.bodies[0].shape.parts: missing for a compound; accepted: "),
    (["scene.bodies.0.shape={type: sphere, center: [0.5,0.5], radius: 0.1, parts: [{type: box}]}"],
     "scene.bodies[0].shape.parts: not used by a sphere; accepted: type, center, radius, inner_radius, rotation; "
     "or parts with a compound"),
    (["kernel=nope"], "kernel=nope: unknown option; accepted: compact, cubic, linear, quadratic"),
    (["kernel.transfer=blend"], "kernel.transfer: 'blend' unknown; accepted: mls, apic, pic, flip"),
    (["kernel.flip=1.5"], "kernel.flip: 1.5 out of range; accepted: kernel.flip >= 0.0, kernel.flip <= 1.0"),
    (["+experiment=impact"], "experiment: impact is a sweep; accepted: run it with -m (python -m pipelines.run -m "
                             "+experiment=impact)"),
    (["material=steel"], "material=steel: unknown option; accepted: fixed_corotated, fluid, nacc, neo_hookean, sand, snow, viscoplastic, viscous, von_mises"),
    (["scene.bodies.0.shape.center=[0.5,0.9]"], "scene.bodies[0]: particles outside the domain"),
    (["scene.bodies.0.shape.radius=0"], "scene.bodies[0].shape.radius: 0.0 out of range"),
    (["scene.bodies.0.material={model: fluid, Kk: 3}"],
     "scene.bodies[0].material.Kk: not a parameter of fluid; accepted: model, rho, K, gamma, viscosity"),
    (["run.precision=float16"], "run.precision: 'float16' unknown; accepted: float32, float64"),
    (["run.device=tpu"], "run.device: 'tpu' unknown; accepted: auto, cpu, cuda"),
    (["run.steps=0"], "run.steps: 0 out of range; accepted: run.steps >= 1"),
    (["run.steps=5", "run.duration=1"], "run.steps: set run.steps or run.duration, not both"),
    (["run.dt=-1"], "run.dt: -1.0 out of range; accepted: run.dt > 0.0"),
    (["run.stepz=3"], "run.stepz: unknown key; accepted: steps, duration, dt"),
    (["material.E=abc"], "material.E: 'abc' is not a number"),
    (["scene.walls=[slip,slip]"], "scene.walls: ['slip', 'slip']; accepted: one of sticky, slip, open"),
    (["scene.walls=glue"], "scene.walls[0]: 'glue' unknown; accepted: sticky, slip, open"),
    (["log.every=-1"], "log.every: -1 out of range; accepted: log.every >= 0"),
    (["material.E=["], "cannot parse the command line"),
    (["scene.bodies.3.velocity=[1,0]"], "scene.bodies[3]: no such element, the index is past the end"),
    # values that passed validation and then hung (run forever, or "complete" at t = 0)
    (["run.duration=inf"], "run.duration: inf is not finite; accepted: a finite number"),
    (["run.duration=nan"], "run.duration: nan is not finite"),
    (["run.duration=-1"], "run.duration: -1.0 out of range; accepted: run.duration > 0.0"),
    (["run.dt=1e-400"], "run.dt: 0.0 out of range; accepted: run.dt > 0.0"),
    # values that ended in a traceback
    (["run.dt=inf"], "run.dt: inf is not finite"),
    (["run.dt=nan"], "run.dt: nan is not finite"),
    (["seed=-1", "scene.jitter=0.5"], "seed: -1 out of range; accepted: seed >= 0"),
    (["seed=abc"], "seed: 'abc' is not an integer"),
    (["log.recording="], "log.recording: ''; accepted: a file name ending in .rrd"),
    (["log.recording=missing/x.rrd"], "log.recording: 'missing/x.rrd'; accepted: a file name ending in .rrd, "
                                      "without a directory"),
    (["scene.resolution=100000"], "scene.resolution: the run needs about"),
    (["scene.ppc=100000"], "scene.ppc: the run needs about"),
    (["run.steps=1e30"], "run.steps: '1e+30' is not an integer"),
    (["run.reference=/nonexistent/final_state.npz"], "run.reference: '/nonexistent/final_state.npz': no "
                                                     "final_state.npz there"),
    # input that was silently ignored
    (["+run.stepz=5"], "run.stepz: unknown key; accepted: cfl, checkpoint_every, compensate, device, dt,"),
    (["+log.evry=3"], "log.evry: unknown key; accepted: channels, color, color_range, dJ, every,"),
    (["+foo=1"], "foo: unknown key; accepted: detect, expected, integrator,"),
    (["+scene.bodies.0.colour=red"], "scene.bodies[0].colour: unknown key; accepted: angular_velocity,"),
    (["+scene.bodies.0.shape.radiuss=1"], "scene.bodies[0].shape.radiuss: unknown key; accepted: axis,"),
    (["+kernel.support=5"], "kernel.support: unknown key; accepted: flip, name, transfer"),
    (["scene.contact_fill=2"], "scene.contact_fill: 2.0 out of range; accepted: scene.contact_fill > 0.0, "
                               "scene.contact_fill <= 1.0"),
    # messages that said too little or blamed the wrong key
    (["material.E=nan"], "material.E: nan is not finite; accepted: a finite number"),
    (["material.nu=nan"], "material.nu: nan is not finite"),
    (["scene.wall_cells=40"], "scene.wall_cells: 40 cells (0.625 m) per face leave no interior along axis 0"),
    (["scene=rotating_plate_2d", "scene.regions.0.body=7"], "scene.regions[0]: no such element"),
    (["log.progress=maybe"], "log.progress: 'maybe' is not true or false; accepted: true, false"),
    # ranges, sizes, names and shapes of every group
    (["run.cfl=0"], "run.cfl: 0.0 out of range; accepted: run.cfl > 0.0, run.cfl <= 1.0"),
    (["run.dt_collapse=2"], "run.dt_collapse: 2.0 out of range"),
    (["run.sync_every=0"], "run.sync_every: 0 out of range; accepted: run.sync_every >= 1"),
    (["run.graph=maybe"], "run.graph: 'maybe' is not true or false; accepted: true, false"),
    (["scene.resolution=2.5"], "scene.resolution: '2.5' is not an integer"),
    (["scene.domain=[0,1]"], "scene.domain[0]: 0.0 out of range; accepted: scene.domain[0] > 0.0"),
    (["scene.gravity=[0]"], "scene.gravity: [0.0]; accepted: a list of 2 numbers"),
    (["scene.lattice_offset=[0.5]"], "scene.lattice_offset: [0.5]; accepted: a list of 2 numbers"),
    (["scene.contact=glue"], "scene.contact: 'glue' unknown; accepted: frictionless, friction, none, shared"),
    (["scene.contact_normal=up"], "scene.contact_normal: 'up' unknown; accepted: difference, max_gradient, stiffer"),
    (["scene.contact_share=1"],
     "scene.contact_share: 1.0 out of range; accepted: scene.contact_share >= 0.0, scene.contact_share < 1.0"),
    (["scene.responses.0.quantity=mass"], "scene.responses[0].quantity: 'mass' unknown; accepted: bottom, top, "
                                          "height, width, front, back, center_x, center_y"),
    (["scene.responses.1.name=peak_compression"],
     "scene.responses[1].name: 'peak_compression'; accepted: a name no other response has"),
    (["scene.responses.0.body=cup"], "scene.responses[0].body: 'cup' unknown; accepted: ball"),
    (["scene.size=huge"], "scene.size: 'huge' unknown for scene elastic_ball_2d; accepted: default, paper"),
    (["scene.bodies.0.velocity=[nan,0]"], "scene.bodies[0].velocity[0]: nan is not finite"),
    (["scene.bodies.0.shape.type=cone"], "scene.bodies[0].shape.type: 'cone' unknown; accepted: box, sphere,"),
    (["scene.bodies.0.deformation=[[1,0],[0,0]]"], "scene.bodies[0].deformation: ((1.0, 0.0), (0.0, 0.0)); "
                                                   "accepted: 2 rows of 2 finite numbers with det F > 0 and every "
                                                   "singular value >= 0.001 (no inverted or degenerate start)"),
    (["scene.bodies.0.deformation=[[-1,0],[0,1]]"], "scene.bodies[0].deformation: ((-1.0, 0.0), (0.0, 1.0)); "
                                                    "accepted: 2 rows of 2 finite numbers with det F > 0"),
    (["scene.bodies.0.deformation=[[1,0],[0,0.0005]]"], "scene.bodies[0].deformation: ((1.0, 0.0), (0.0, 0.0005)); "
                                                        "accepted: 2 rows"),
    (["scene.bodies=[]"], "scene.bodies: empty; accepted: at least one body"),
    (["integrator=implicit", "integrator.newton_max=0"], "integrator.newton_max: 0 out of range"),
    (["scheme=aulmpm", "scheme.criterion=foo"], "scheme.criterion: 'foo' unknown; accepted: paper, distortion"),
    (["detect.speed_factor=0"], "detect.speed_factor: 0.0 out of range; accepted: 0.0 < speed_factor"),
    (["scene=viscous_cup", "scene.colliders.0.boundary=glue"],
     "scene.colliders[0].boundary: 'glue' unknown; accepted: sticky, slip, separate"),
    (["log.fps=0"], "log.fps: 0.0 out of range; accepted: log.fps > 0.0"),
    (["log.color=rainbow"], "log.color: 'rainbow'; accepted: auto, body, dJ"),
    (["log.color=plastic_strain"], "log.color: 'plastic_strain' (no plastic body in this scene)"),
    (["hydra.run.dir=/proc/no/run"], "hydra.run.dir: cannot create /proc/no"),
    # selections, meshes, option types and nested keys: refused before the run directory is written
    (["scene=cantilever_2d", "scene.loads.0.select.center=[0.2,0.1]"],
     "scene.loads[0].select: load 'tip' selects no particle of body 'beam'"),
    (["scene=cantilever_2d", "scene.regions.0.select.center=[0.2,0.1]"],
     "scene.regions[0].select: region 'clamp' selects no particle of body 'beam'"),
    (["scene.bodies.0.shape.radius=0.001"], "scene.bodies[0].shape: body 'ball' holds no particle"),
    (["scene=yoyo", "scene.bodies.0.shape.parts.0.mesh=conf"], "scene.bodies[0].shape.parts[0].mesh: 'conf': a "
                                                                "directory"),
    (["integrator=implicit", "integrator.cg_max=many"], "integrator.cg_max: 'many' is not an integer"),
    (["+scale.nope=1"], "scale.nope: unknown key; accepted: bar_grids,"),
    (["log.dJ=2"], "log.dJ: 2 is not true or false; accepted: true, false"),
    (["scene=1"], "scene: '1' is not an option's name; accepted: ball_in_cylinder,"),
    (["scene.bodies.0.ppc=100000"], "scene.bodies[0].ppc: the run needs about"),
]


# also run in a process of their own, like any command line
OWN_PROCESS = [["material.Ee=1"], ["scene=nope"], ["+foo=1"], ["scene.resolution=100000"],
               ["hydra.run.dir=/proc/no/run"]]


def _check_refusal(message, code, stderr, out) -> str | None:
    """Why an outcome is not a one-line refusal ``error: <message>...`` with
    exit code 2 that leaves ``out`` absent (None: it is)."""
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if code != 2:
        return f"exit code {code}: {stderr}"
    if lines != lines[:1] or not lines[0].startswith(f"error: {message}"):
        return f"not the one line 'error: {message}...': {stderr}"
    if "Traceback" in stderr:
        return stderr
    if out is not None and out.exists():
        return f"left {out} behind"
    return None


def _with_run_dir(args, out):
    """``args`` with the run directory ``out``, unless they name their own;
    and the directory that must stay absent (None: their own)."""
    if any(a.startswith("hydra.run.dir=") for a in args):
        return args, None
    return args + [f"hydra.run.dir={out}"], out


@pytest.mark.slow
def test_bad_input_is_one_line_and_exit_2(tmp_path):
    """Every BAD_INPUTS entry, each through pipelines.run's main as from a
    fresh process, all in one process (tests/cli_batch.py: a process per
    command line costs seconds of imports each)."""
    cases = [_with_run_dir(args, tmp_path / str(i)) for i, (args, _) in enumerate(BAD_INPUTS)]
    (tmp_path / "in.json").write_text(json.dumps([argv for argv, _ in cases]))
    p = subprocess.run([sys.executable, str(ROOT / "tests" / "cli_batch.py"), str(tmp_path / "in.json"),
                        str(tmp_path / "out.json")], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    results = json.loads((tmp_path / "out.json").read_text())
    wrong = {" ".join(args): why for (args, message), (_, out), (code, stderr) in zip(BAD_INPUTS, cases, results)
             if (why := _check_refusal(message, code, stderr, out))}
    assert not wrong, "\n".join(f"{k}: {v}" for k, v in wrong.items())


@pytest.mark.parametrize("args", OWN_PROCESS, ids=" ".join)
def test_bad_input_from_a_fresh_process(args, tmp_path):
    message = next(m for a, m in BAD_INPUTS if a == args)
    argv, out = _with_run_dir(args, tmp_path / "run")
    p = run_cli(argv, cwd=ROOT, timeout=120)
    why = _check_refusal(message, p.returncode, p.stderr, out)
    assert why is None, why


# documented outcomes of inputs that are not errors: (args, exit code, a stderr
# fragment, a check of the run directory: metrics.json's contents and the run's files)


def _same_as_without_the_override(m, run):
    """The plate ran with its own material: its final state is that of the
    same run without material.E=5 (in-process), to float32 round-off."""
    import numpy as np

    from helpers import spec_for
    from pipelines.run.runner import execute

    ref = execute(spec_for(["scene.resolution=24", "scene=rotating_plate_2d", "run.steps=2", "log.every=0"]),
                  run.parent / "reference")
    got, want = np.load(run / "final_state.npz"), np.load(run.parent / "reference" / "final_state.npz")
    eps = np.finfo(np.float32).eps
    return (m["status"] == ref["status"] == "completed" and m["dt"] == ref["dt"]
            and np.allclose(got["x"], want["x"], rtol=0, atol=4 * eps)
            and np.allclose(got["v"], want["v"], rtol=0, atol=64 * eps * np.abs(want["v"]).max()))


def _left_through_the_open_face(m, run):
    """The removed particles are the massless ones of the final state, each
    parked where it crossed the open x_hi face's interior bound (1 - dx:
    one cell from the face, dx = 1/24), none elsewhere."""
    import numpy as np

    f = np.load(run / "final_state.npz")
    gone = f["mass"] == 0
    return (m["status"] == "completed" and m["removed"]["total"] == gone.sum() > 0
            and np.allclose(f["x"][gone, 0], 1 - 1 / 24, rtol=0, atol=4 * np.finfo(np.float32).eps))


BEHAVIOURS = [
    # an initial velocity that overflows float32: unstable at step 0, not a hang
    (["scene.bodies.0.velocity=[1e30,0]"], 3, "kinetic or potential energy is not finite",
     lambda m, run: m["status"] == "unstable" and m["unstable_step"] == 0 and m["unstable_criterion"] == "nonfinite"),
    # an override the scene cannot use is said, and the run goes ahead
    (["scene=rotating_plate_2d", "material.E=5", "run.steps=2"], 0,
     "note: material.E=5 has no effect: every body of scene rotating_plate_2d brings its own material",
     _same_as_without_the_override),
    # an open wall removes the particles that leave through it
    (["scene.walls=[slip,open,slip,slip]", "scene.gravity=[0,0]", "scene.bodies.0.velocity=[8,0]",
      "run.duration=0.05"], 0, "completed", _left_through_the_open_face),
    # epsilon = inf: A-ULMPM never updates (it is TLMPM), even with eta = 0, where
    # a finite epsilon updates at every step
    (["scheme=aulmpm", "scheme.epsilon=inf", "scheme.eta=0", "run.steps=3"], 0, "completed",
     lambda m, run: m["steps"] == 3 and m["config_updates"]["total"] == 0),
    # a recording larger than log.size_warning_mb is announced before the run, with
    # an estimate of at least its particle frames' payload (positions and dJ, float32)
    (["run.steps=2", "log.size_warning_mb=0.01"], 0, "warning: the recording will be about",
     lambda m, run: m["recording_estimate_mb"] > 0.01
     and m["recording_estimate_mb"] >= 3 * m["particles"] * (2 + 1) * 4 / 1e6),
]


@pytest.mark.parametrize("args,code,fragment,check", BEHAVIOURS, ids=[" ".join(a)[:60] for a, *_ in BEHAVIOURS])
def test_documented_behaviour(args, code, fragment, check, tmp_path):
    run = tmp_path / "run"
    p = run_cli(["scene.resolution=24", "log.progress=false"] + args + [f"hydra.run.dir={run}"], cwd=ROOT,
                timeout=300)
    assert p.returncode == code, p.stderr
    assert fragment in p.stderr and "Traceback" not in p.stderr, p.stderr
    assert check(json.loads((run / "metrics.json").read_text()), run)
    verify(run / "recording.rrd")


def test_finite_epsilon_with_eta_zero_updates_every_step(tmp_path):
    """The other side of the epsilon = inf behaviour: the same run with
    epsilon = 0 updates at every one of its steps (the check above can fail)."""
    from helpers import spec_for
    from pipelines.run.runner import execute

    m = execute(spec_for(["scene.resolution=24", "scheme=aulmpm", "scheme.epsilon=0", "scheme.eta=0",
                          "run.steps=3", "log.every=0"]), tmp_path)
    assert m["config_updates"]["total"] == 3


def test_an_override_the_run_cannot_use_is_said():
    """kernel.flip is the blend of transfer=flip: with another transfer it
    has no effect, said (a note) rather than ignored."""
    from helpers import spec_for
    from pipelines.run.__main__ import unused_overrides

    args = ["kernel.flip=0.5"]
    notes = unused_overrides(spec_for(args), args)
    assert notes == ["kernel.flip=0.5 has no effect: it is the blend of kernel.transfer=flip, and this run's transfer "
                     "is mls (add kernel.transfer=flip)"]
    args = ["kernel.transfer=flip", "kernel.flip=0.5"]
    assert unused_overrides(spec_for(args), args) == []


def test_the_cli_table_covers_sixty_inputs():
    assert len(BAD_INPUTS) + len(BEHAVIOURS) >= 60


def verify(path: Path) -> None:
    p = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr


def test_unstable_run_stops_cleanly(tmp_path):
    # a far too large fixed time step for a stiff ball
    p = run_cli(["material.E=1e8", "run.dt=2e-3", "run.steps=500", "scene.resolution=32",
                 f"hydra.run.dir={tmp_path}"], cwd=ROOT)
    assert p.returncode == 3, p.stderr
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["status"] == "unstable"
    assert metrics["reason"].startswith(f"step {metrics['unstable_step']} (t = ")
    assert metrics["steps"] == metrics["unstable_step"] < 500
    # caught by the blow-up detection (mpm.stepping.detection), or at the latest when values turn non-finite
    assert metrics["unstable_criterion"] in ("energy", "speed", "nonfinite", "outside")
    assert metrics["reason"] in p.stderr
    verify(tmp_path / "recording.rrd")


def test_collapsing_time_step_stops_as_unstable(tmp_path):
    """A run whose adaptive step keeps shrinking (here: a ball speeding up
    under gravity against a threshold of 0.95 of the first step; in practice a
    particle's strain rate running away) stops instead of crawling forever."""
    p = run_cli(["scene.resolution=32", "run.dt_max=1", "run.dt_collapse=0.95", "run.steps=2000",
                 f"hydra.run.dir={tmp_path}"], cwd=ROOT)
    assert p.returncode == 3, p.stderr
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["status"] == "unstable" and "time step collapsed" in metrics["reason"]
    assert 1 < metrics["steps"] < 2000 and metrics["dt_min"] < metrics["dt_max"]
    verify(tmp_path / "recording.rrd")


def test_a_large_energy_loss_is_reported(tmp_path):
    """metrics.json energy_change = (E_final - E_initial - boundary work) /
    energy scale; a loss of more than ENERGY_LOSS_NOTE of the scale is said on
    the run's last lines. The soft ball (E = 1e3 Pa) hitting the floor in
    EMPM loses 1.2 of its scale (measured); the default ball's first 300
    steps lose 0.3 % of it, which is not reported."""
    from pipelines.run.__main__ import ENERGY_LOSS_NOTE

    soft = run_cli(["scene=stability_ball_2d", "material.E=1e3", "run.duration=0.5", "log.every=0",
                    "log.progress=false", f"hydra.run.dir={tmp_path / 'soft'}"], cwd=ROOT)
    assert soft.returncode == 0, soft.stderr
    m = json.loads((tmp_path / "soft" / "metrics.json").read_text())
    d = m["detect"]
    assert m["energy_change"] == pytest.approx(
        (m["energy_final"] - m["energy_initial"] - d["boundary_work"]) / d["energy_scale"], rel=1e-12)
    assert m["energy_change"] < -1.0
    assert f"note: the total energy fell by {-m['energy_change']:.2g} of its scale" in soft.stderr
    ball = run_cli(["run.steps=300", "log.every=0", "log.progress=false", f"hydra.run.dir={tmp_path / 'ball'}"],
                   cwd=ROOT)
    m = json.loads((tmp_path / "ball" / "metrics.json").read_text())
    assert -ENERGY_LOSS_NOTE < m["energy_change"] < 0 and "note: the total energy" not in ball.stderr


@pytest.mark.parametrize("sig,name,code,status", [(signal.SIGINT, "Ctrl-C", 130, "interrupted"),
                                                  (signal.SIGTERM, "SIGTERM", 75, "preempted")])
def test_interrupt_leaves_recording_and_metrics(sig, name, code, status, tmp_path):
    """Ctrl-C ends a run; SIGTERM pre-empts it: a checkpoint first (pipelines.run.checkpoints), exit code 75."""
    rrd = tmp_path / "recording.rrd"
    proc = subprocess.Popen([sys.executable, "-m", "pipelines.run", "run.steps=10000000",
                             "log.every=20", f"hydra.run.dir={tmp_path}"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 300
        while time.time() < deadline and (not rrd.exists() or rrd.stat().st_size < 200_000):
            time.sleep(0.2)  # wait until it is stepping and logging
        assert proc.poll() is None
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == code, err
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["status"] == status and metrics["reason"].startswith(f"{name} at step")
    assert (f"checkpoint {tmp_path / 'checkpoints'}" in metrics["reason"]) == (status == "preempted")
    assert metrics["steps"] > 0 and math.isfinite(metrics["energy_final"])
    verify(rrd)


def test_a_signal_landing_in_a_finaliser_is_not_lost():
    """Python ignores an exception raised in __del__; Warp arrays die every
    step. In the step loop a signal is therefore remembered and raised at the
    next step boundary; a second one raises at once."""
    from pipelines.run.runner import Interrupts

    interrupts = Interrupts()
    interrupts.deferred = True

    class Dying:
        def __del__(self):
            interrupts.handler(signal.SIGTERM, None)

    Dying()  # the handler runs inside a finaliser: nothing may be raised there
    with pytest.raises(KeyboardInterrupt) as info:
        interrupts.check()
    assert type(info.value).__name__ == "_Terminate"  # reported as SIGTERM
    interrupts.check()  # raised once
    interrupts.handler(signal.SIGINT, None)
    with pytest.raises(KeyboardInterrupt):  # a second one while one is pending
        interrupts.handler(signal.SIGINT, None)


@pytest.mark.slow
def test_the_plan_names_the_stages_a_scene_needs_and_runs_nothing(tmp_path):
    one = run_cli(["run.plan=true", f"hydra.run.dir={tmp_path / 'a'}"], cwd=ROOT, timeout=120)
    assert one.returncode == 0, one.stderr
    # the default EMPM with the quadratic kernel: fused, no update pass (run.fuse null)
    assert "P2G (1 material group(s); stencils located on the fly; node positions on the lattice)" in one.stdout
    assert "configuration update: every step, in G2P" in one.stdout
    assert "contact" not in one.stdout and "removal" not in one.stdout and "implicit" not in one.stdout
    assert not (tmp_path / "a").exists()  # nothing was run
    two = run_cli(["run.plan=true", "scene=falling_bodies", "scheme=aulmpm", "scene.walls=open",
                   f"hydra.run.dir={tmp_path / 'b'}"], cwd=ROOT, timeout=120)
    assert two.returncode == 0, two.stderr
    assert "stencils from the cache; node positions summed)" in two.stdout and "contact between bodies" in two.stdout
    assert "removal at open walls" in two.stdout and "when the criterion fires" in two.stdout
    three = run_cli(["run.plan=true", "scheme=tlmpm", f"hydra.run.dir={tmp_path / 'c'}"], cwd=ROOT, timeout=120)
    assert three.returncode == 0, three.stderr
    assert "node positions summed only in steps near a wall" in three.stdout  # walls alone
    four = run_cli(["run.plan=true", "kernel=compact", f"hydra.run.dir={tmp_path / 'd'}"], cwd=ROOT, timeout=120)
    assert four.returncode == 0, four.stderr  # the compact kernel keeps its cache and its update pass
    assert "stencils from the cache" in four.stdout and "configuration update: every step; the host" in four.stdout


def test_a_group_option_switched_by_its_name_is_recorded_as_run(tmp_path):
    """``scheme.name=aulmpm`` in the default scheme option runs A-ULMPM with
    its defaults; Hydra records the group's choice (empm), so the run says
    so, and its directory and recorded choices name what ran."""
    from pipelines.recording import recordings

    p = run_cli(["scheme.name=aulmpm", "run.steps=1", "log.progress=false"], cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "note: scheme.name=aulmpm set by key in the scheme option empm" in p.stderr
    run, = (tmp_path / "outputs").glob("*/*")
    assert run.name.endswith("_elastic_ball_2d_aulmpm")
    choices = recordings.read(run / "recording.rrd").properties["config:choices"]
    assert "scheme=aulmpm" in choices and "scheme=empm" not in choices
