"""Checkpoints (mpm.checkpoint): a run saved after k steps and resumed in a
fresh driver ends bit for bit where the uninterrupted run ends, for every
scheme, the implicit integrator, friction contact, a plastic model, a ramped
load, FLIP and batched steps; a damaged file, another configuration and a
driver that has not started are refused in one line; a failed write leaves
the previous checkpoint whole."""

import os
import sys

import numpy as np
import pytest

import mpm
from mpm import checkpoint

pytestmark = pytest.mark.bitwise

FIELDS = ("x", "v", "C", "F0s", "Fsn", "X", "dJ", "history")


class Updates(mpm.Observer):
    """The steps at which a body's reference configuration was updated, and the resumes seen."""

    def __init__(self):
        self.updated, self.touching, self.resumed = [], [], 0

    def on_step(self, driver, report):
        if report.updated or report.regrid:
            self.updated.append(driver.step)
        if report.contact_nodes:
            self.touching.append(driver.step)

    def on_resume(self, driver):
        self.resumed += 1


def ball(material=None, **keys):
    body = mpm.Body(mpm.Sphere((0.5, 0.35), 0.1), material or mpm.NeoHookean(E=1e5, nu=0.3), velocity=(0.5, 0.0))
    return mpm.Scene(**{"dim": 2, "domain": (1.0, 1.0), "resolution": 16, "gravity": (0.0, -9.81),
                        "bodies": [body], **keys})


def droplet():
    """A drop thrown at the floor: A-ULMPM updates its reference from the second step on."""
    body = mpm.Body(mpm.Sphere((0.5, 0.3), 0.1), mpm.Fluid(K=2e4), velocity=(0.0, -3.0))
    return mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, gravity=(0.0, -9.81), bodies=[body])


def two_blocks(contact="friction"):
    """A block dropped onto another with Coulomb friction between them."""
    low = mpm.Body(mpm.Box((0.5, 0.3), (0.15, 0.06)), mpm.NeoHookean(E=1e5, nu=0.3))
    high = mpm.Body(mpm.Box((0.45, 0.43), (0.06, 0.06)), mpm.NeoHookean(E=1e5, nu=0.3), velocity=(0.5, -1.0))
    return mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, gravity=(0.0, -9.81), bodies=[low, high],
                     contact=contact, contact_friction=0.4)


CASES = {  # name: (scene, scheme, options, sync_every)
    "empm": (ball, mpm.EMPM, {}, 1),
    "tlmpm": (ball, mpm.TLMPM, {}, 1),
    "aulmpm_droplet": (droplet, mpm.AULMPM, {}, 1),
    "aulmpm_batched": (droplet, mpm.AULMPM, {"batched": True}, 4),
    "implicit": (ball, mpm.AULMPM, {"integrator": mpm.Implicit()}, 1),
    "implicit_plastic": (lambda: ball(mpm.VonMises(E=1e5, nu=0.3, yield_stress=2e2)), mpm.EMPM,
                         {"integrator": mpm.Implicit()}, 1),
    "friction": (two_blocks, mpm.AULMPM, {}, 1),
    "plastic": (lambda: ball(mpm.VonMises(E=1e5, nu=0.3, yield_stress=2e2)), mpm.AULMPM, {}, 1),
    "ramped_load": (lambda: ball(loads=[mpm.Load.point(force=(0.0, -20.0), at=(0.5, 0.45), count=4, ramp=0.01)]),
                    mpm.AULMPM, {}, 1),
    "flip": (ball, mpm.EMPM, {"transfer": "flip"}, 1),
    # a rigid disc (mpm.rigid) striking the ball: its Newton state is the run's too
    "rigid": (lambda: ball(rigid_bodies=[mpm.RigidBody(mpm.Collider.sphere((0.5, 0.52), 0.05), density=800.0,
                                                       velocity=(0.0, -3.0), angular_velocity=1.0)]),
              mpm.EMPM, {}, 1),
    # the ball rolling on an elastic plane (mpm.elastic_contact): its springs' travel and sampled overlap are
    # the run's too
    "elastic": (lambda: ball(colliders=[mpm.Collider.half_space((0.5, 0.252), (0.0, 1.0), boundary="elastic",
                                                                friction=0.5)]), mpm.EMPM, {}, 1),
    # the blocks meeting through springs on their particles (mpm.body_springs): their travel and sampled
    # overlap are the run's too
    "elastic_bodies": (lambda: two_blocks("elastic"), mpm.AULMPM, {}, 1),
    # the disc hinged (mpm.joints): Newton's generalized state (joint_q, joint_qd) is the run's too
    "hinged": (lambda: ball(rigid_bodies=[mpm.RigidBody(mpm.Collider.sphere((0.5, 0.52), 0.05), density=800.0,
                                                        angular_velocity=-8.0, name="disc")],
                            joints=[mpm.Joint("disc", (0.3, 0.52))]), mpm.EMPM, {}, 1),
}
STEPS, SAVE_AT = 24, 10


def make(case, steps=STEPS, observers=()):
    scene, scheme, options, k = CASES[case]
    model, state = mpm.build(scene(), mpm.QUADRATIC, "float32", "cpu")
    solver = mpm.Solver(model, scheme(), mpm.SolverOptions(**options))
    return mpm.Driver(solver, state, mpm.StepPolicy(steps=steps), observers=list(observers), sync_every=k)


def started(case, steps=SAVE_AT):
    driver = make(case)
    driver.start()
    while driver.step < steps and driver.running:
        driver.advance()
    return driver


@pytest.mark.parametrize("case", list(CASES))
def test_a_resumed_run_ends_where_the_whole_run_ends_bit_for_bit(case, tmp_path):
    whole_updates = Updates()
    whole = make(case, observers=[whole_updates])
    assert whole.run().status == "completed"
    first = started(case)
    path = first.save(tmp_path / "ckpt.npz", meta={"config": "abc"})
    assert first.step >= SAVE_AT
    if case.startswith("aulmpm"):  # the reference moved before the save
        assert [s for s in whole_updates.updated if s <= first.step], whole_updates.updated
    if case == "friction":  # the blocks touched before the save
        assert [s for s in whole_updates.touching if s <= first.step], whole_updates.touching
    seen = Updates()
    fresh = make(case, observers=[seen])
    data = fresh.resume(path)
    assert (data.step, data.time, data.meta) == (first.step, first.time, {"config": "abc"})
    assert seen.resumed == 1 and (fresh.step, fresh.time) == (first.step, first.time)
    assert fresh.run().status == "completed"
    assert (fresh.step, fresh.time, fresh.dts) == (whole.step, whole.time, whole.dts)
    for name in FIELDS:
        a, b = getattr(whole.state, name).numpy(), getattr(fresh.state, name).numpy()
        assert np.array_equal(a, b), f"{case}: state.{name} differs after the resume"
    assert np.array_equal(whole.solver.layout.lo, fresh.solver.layout.lo)
    if case == "rigid":  # the disc struck the ball before the save
        coupler = first.solver.conditions.rigid
        assert coupler.poses()["velocity"][0][1] > -3.0 + 9.81 * first.time + 1e-3
    if case == "hinged":  # the disc turned about its hinge before the save
        assert first.solver.conditions.rigid.joint_q.numpy()[0] < -0.01
    if case == "elastic":  # the ball touched the plane before the save, and its springs' state ends the same
        assert np.any(first.solver.transfers.springs.w.numpy() != 0.0)
        for name in ("w", "lap"):
            a, b = (getattr(d.solver.transfers.springs, name).numpy() for d in (whole, fresh))
            assert np.array_equal(a, b), f"elastic: springs.{name} differs after the resume"
    if case == "elastic_bodies":  # the blocks touched before the save, and their springs' state ends the same
        assert np.any(first.solver.transfers.touching.w.numpy() != 0.0)
        for name in ("w", "lap"):
            a, b = (getattr(d.solver.transfers.touching, name).numpy() for d in (whole, fresh))
            assert np.array_equal(a, b), f"elastic_bodies: touching.{name} differs after the resume"
    if case in ("rigid", "hinged"):  # the disc ends where the whole run's does
        for name in ("body_q", "body_qd") + (("joint_q", "joint_qd") if case == "hinged" else ()):
            a, b = (getattr(d.solver.conditions.rigid, name).numpy() for d in (whole, fresh))
            assert np.array_equal(a, b), f"rigid: {name} differs after the resume"
    assert dict(whole.binding) == dict(fresh.binding) and whole.summary() == fresh.summary()


def test_what_is_kept_and_what_is_not(tmp_path):
    """The state's arrays and the layout are kept by path; the grid's scratch fields are not."""
    driver = started("aulmpm_droplet", 3)
    sig = checkpoint.signature(driver)
    assert {"state.x", "state.F0s", "state.history", "solver.layout.lo", "solver.X0"} <= set(sig)
    assert sig["state.x"][:2] == ("array", (driver.state.x.shape[0],))
    assert not [p for p in sig if p.startswith("solver.grid")], "the grid's nodal fields are scratch"
    path = driver.save(tmp_path / "a.npz")
    data = checkpoint.read(path)
    assert data.header["format"] == checkpoint.FORMAT and data.header["signature"] == sig
    assert np.array_equal(data.arrays["state.x"], driver.state.x.numpy())
    values = data.header["values"]
    assert (data.step, values["step"], values["time"], values["dts"]) == (3, 3, driver.time, driver.dts)


def test_a_damaged_file_or_another_configuration_is_refused_in_one_line(tmp_path):
    driver = started("empm", 2)
    path = driver.save(tmp_path / "ckpt.npz")
    cut = tmp_path / "cut.npz"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    for bad, said in [(cut, "damaged"), (tmp_path / "none.npz", "no such file")]:
        with pytest.raises(checkpoint.CheckpointError) as e:
            make("empm").resume(bad)
        assert said in str(e.value) and "\n" not in str(e.value), str(e.value)
    with pytest.raises(checkpoint.CheckpointError) as e:  # another scene: another particle count
        make("friction").resume(path)
    assert "another configuration" in str(e.value) and "\n" not in str(e.value), str(e.value)
    with pytest.raises(checkpoint.CheckpointError) as e:  # the same arrays of another precision
        model, state = mpm.build(ball(), mpm.QUADRATIC, "float64", "cpu")
        mpm.Driver(mpm.Solver(model, mpm.EMPM()), state, mpm.StepPolicy(steps=STEPS)).resume(path)
    assert "another configuration (" in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_file_of_another_format_version_is_refused(tmp_path, monkeypatch):
    driver = started("empm", 1)
    monkeypatch.setattr(checkpoint, "FORMAT", checkpoint.FORMAT + 1)
    path = driver.save(tmp_path / "ckpt.npz")
    monkeypatch.undo()
    with pytest.raises(checkpoint.CheckpointError, match="format version 2; accepted: 1"):
        checkpoint.read(path)


@pytest.mark.skipif(sys.platform == "win32" or os.geteuid() == 0, reason="root writes anywhere")
def test_a_failed_write_keeps_the_previous_checkpoint_whole_unwritable(tmp_path):
    driver = started("empm", 1)
    path = driver.save(tmp_path / "ckpt.npz")
    before = path.read_bytes()
    os.chmod(tmp_path, 0o500)
    try:
        with pytest.raises(PermissionError):
            driver.save(path)
    finally:
        os.chmod(tmp_path, 0o700)
    assert path.read_bytes() == before


def test_a_write_that_fails_midway_keeps_the_previous_checkpoint_and_leaves_no_temporary(tmp_path, monkeypatch):
    driver = started("empm", 1)
    path = driver.save(tmp_path / "ckpt.npz")
    before = path.read_bytes()
    driver.advance()

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full)
    with pytest.raises(OSError, match="No space left"):
        driver.save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["ckpt.npz"]
    assert checkpoint.read(path).step == 1


def test_save_before_start_inside_a_batch_and_resume_after_start_are_refused(tmp_path):
    with pytest.raises(RuntimeError, match="^save: the driver has not started"):
        make("empm").save(tmp_path / "ckpt.npz")
    batched = started("aulmpm_batched", 1)
    batched.current = False  # (as an observer sees it at a step inside a batch)
    with pytest.raises(RuntimeError, match="^save: the device holds a later step"):
        batched.save(tmp_path / "inside.npz")
    assert not (tmp_path / "inside.npz").exists()
    driver = started("empm", 1)
    path = driver.save(tmp_path / "ckpt.npz")
    with pytest.raises(RuntimeError, match="^resume: the driver has started"):
        driver.resume(path)
