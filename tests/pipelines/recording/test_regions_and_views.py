"""The replay's frames, looked at: kinematic regions outlined (with a legend
entry) in 2D, in every projection and in 3D perspective, where their
particles are at the frame's time; and the projections of a 3D recording
oriented as they say, the particles nearest the viewer drawn last."""

import dataclasses

import numpy as np
import pytest
import yaml
from PIL import Image

from pipelines.recording import recordings, regions
from pipelines.recording.display import projection, render_frames
from pipelines.recording.colours import PALETTE, PALETTE_PACKED

MAGENTA = np.round(np.array(regions.EDGE) * 255).astype(np.int32)


def pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int32)


def mask(img, rgb, tol=30) -> np.ndarray:
    return np.all(np.abs(img - np.asarray(rgb, np.int32)) <= tol, axis=-1)


def synthetic(positions: list, body: np.ndarray, domain, scene: dict | None = None, times=None):
    """A recording of particle frames ``positions`` (bodies ``body``) and a
    recorded config holding ``scene`` (its domain set)."""
    config = {"scene": {"dim": len(domain), "domain": list(domain), **(scene or {})}}
    n = len(positions)
    return recordings.Recording(
        steps=np.arange(n), times=np.asarray(times if times is not None else np.arange(n) * 0.1, float),
        positions=positions, dJ=[None] * n, fields=[{}] * n, body=body, colors=PALETTE_PACKED[body % 10],
        scalars={}, properties={"config:yaml": [yaml.safe_dump(config)]}, update_steps=np.zeros(0, np.int64),
        colliders={}, radius=0.006)


def slab(lo, hi, h=0.01) -> np.ndarray:
    """Particles filling the box [lo, hi] on a lattice of spacing ``h``."""
    axes = [np.arange(a + h / 2, b, h) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lo))


# ---------------------------------------------------------------- kinematic regions

CLAMP = {"name": "clamp", "body": "beam", "select": {"type": "box", "center": [0.2, 0.7], "half_size": [0.05, 0.06]},
         "velocity": [0.0, 0.0]}


def test_a_2d_region_is_outlined_where_it_is_with_a_legend_entry(tmp_path):
    """The cantilever's clamp (conf/scene/cantilever_2d.yaml): a magenta
    rectangle of the clamp's proportions in the left of the picture, and a
    legend entry of the same colour at the upper right; none without regions."""
    beam = slab((0.15, 0.65), (1.05, 0.75))
    rec = synthetic([beam], np.zeros(len(beam), np.int64), (1.2, 0.9), {"regions": [CLAMP]})
    img = pixels(render_frames(rec, tmp_path / "with")[0])
    m = mask(img, MAGENTA)
    half = img.shape[1] // 2
    r, c = np.nonzero(m[:, :half])  # the outline (the legend is on the right)
    assert len(r) > 100
    width, height = c.max() - c.min(), r.max() - r.min()
    assert width / height == pytest.approx(0.05 / 0.06, rel=0.15)
    rl, cl = np.nonzero(m[:, half:])  # the legend's line
    assert len(rl) > 10 and rl.mean() < img.shape[0] / 3
    # the box is at x = 0.15 .. 0.25 of 1.2 m: a tenth of the beam's drawn length from its left end
    beam_cols = np.nonzero(mask(img, PALETTE[0]).any(axis=0))[0]
    per_metre = (beam_cols.max() - beam_cols.min()) / 0.9
    assert (c.min() - beam_cols.min()) / per_metre == pytest.approx(0.0, abs=0.02)
    assert width / per_metre == pytest.approx(0.1, rel=0.1)
    bare = dataclasses.replace(rec, properties={"config:yaml": [yaml.safe_dump({"scene": {"domain": [1.2, 0.9]}})]})
    assert not mask(pixels(render_frames(bare, tmp_path / "without")[0]), MAGENTA).any()


def twisted_bar():
    """A 3D bar with its two end regions (conf/scene/twisting_bar.yaml), two frames."""
    bar = slab((0.2, 0.44, 0.44), (0.8, 0.56, 0.56), 0.02)
    ends = [{"name": name, "body": "bar", "select": {"type": "box", "center": [x, 0.5, 0.5],
                                                     "half_size": [0.025, 0.07, 0.07]},
             "velocity": [u, 0.0, 0.0], "angular_velocity": [w, 0.0, 0.0], **extra}
            for name, x, u, w, extra in (("left_end", 0.225, -0.03, -9.4248, {}),
                                        ("right_end", 0.775, 0.03, 9.4248, {"end": 0.05}))]
    return synthetic([bar, bar], np.zeros(len(bar), np.int64), (1.0, 1.0, 1.0), {"regions": ends},
                     times=[0.0, 1.0 / 12])


@pytest.mark.parametrize("view", ["3d", "xy", "xz", "zy"])
def test_3d_regions_are_outlined_in_every_view(tmp_path, view):
    rec = twisted_bar()
    frames = render_frames(rec, tmp_path / "with", view=view)
    bare = dataclasses.replace(rec, properties={"config:yaml": [yaml.safe_dump({"scene": {"domain": [1.0] * 3}})]})
    without = render_frames(bare, tmp_path / "without", view=view)
    for f, g in zip(frames, without):
        drawn = mask(pixels(f), MAGENTA)
        assert drawn.sum() > 150, drawn.sum()
        assert not mask(pixels(g), MAGENTA).any()
    # the left end turns (an eighth of a turn after 1/12 s: 1.5 turns per second) and the picture changes
    assert (mask(pixels(frames[0]), MAGENTA) != mask(pixels(frames[1]), MAGENTA)).sum() > 50


def test_a_region_moves_with_its_velocity_and_rotation_and_stops_at_its_end():
    """The outline at t: c + u tau + R(w tau) (x0 - c), tau = min(t, end) - start."""
    rec = twisted_bar()
    left, right = regions.regions(rec)
    assert (left.name, right.name) == ("left_end", "right_end")
    t = 1.0 / 12
    corner0 = left.outline(0.0, 3)[0][0]  # a corner of the box at the start
    a = -9.4248 * t  # about x
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    expected = left.center + np.array([-0.03 * t, 0, 0]) + R @ (corner0 - left.center)
    assert np.allclose(left.outline(t, 3)[0][0], expected, atol=1e-12)
    assert left.active(t) and not right.active(t)  # the right end let go at 0.05 s: drawn where it stopped
    assert np.allclose(right.outline(t, 3)[0], right.outline(0.05, 3)[0])


# ---------------------------------------------------------------- projections

def two_layers(first, second):
    a, b = slab(*first), slab(*second)
    body = np.r_[np.zeros(len(a), np.int64), np.ones(len(b), np.int64)]
    return synthetic([np.concatenate([a, b])], body, (1.0, 1.0, 1.0))


def test_the_projections_state_a_right_handed_convention():
    """Across x up the picture points towards the viewer: xy from +z, xz
    from above (+y, z down the picture), zy from -x."""
    e = np.eye(3)
    for view, seen in (("xy", "+z"), ("xz", "+y"), ("zy", "-x")):
        p = projection(view)
        a, b = p["axes"]
        toward = np.cross(e[a], -e[b] if p["down"] else e[b])
        assert toward[p["depth"]] == p["sign"] and seen in p["seen"]
    assert projection("xz")["down"] and not projection("xy")["down"] and not projection("zy")["down"]


def test_xz_is_seen_from_above_with_z_down_the_picture(tmp_path):
    """Two layers: a high one (body 1, y = 0.6) over the low one's (body 0,
    y = 0.1) half nearest z = 0. Seen from above, the high layer hides that
    half and lies in the upper half of the picture (z down); the low
    layer's other half shows below it, equal areas."""
    rec = two_layers(((0.2, 0.1, 0.2), (0.8, 0.12, 0.8)), ((0.2, 0.6, 0.2), (0.8, 0.62, 0.5)))
    img = pixels(render_frames(rec, tmp_path / "xz", view="xz")[0])
    low, high = mask(img, PALETTE[0]), mask(img, PALETTE[1])
    assert high.sum() > 2000 and 0.8 < high.sum() / low.sum() < 1.25
    assert np.nonzero(high)[0].mean() < np.nonzero(low)[0].mean()  # image rows grow downwards


@pytest.mark.parametrize("view, near, far", [
    ("xy", ((0.2, 0.2, 0.7), (0.8, 0.8, 0.72)), ((0.2, 0.2, 0.2), (0.8, 0.8, 0.22))),  # from +z
    ("xz", ((0.2, 0.7, 0.2), (0.8, 0.72, 0.8)), ((0.2, 0.2, 0.2), (0.8, 0.22, 0.8))),  # from +y
    ("zy", ((0.2, 0.2, 0.2), (0.22, 0.8, 0.8)), ((0.7, 0.2, 0.2), (0.72, 0.8, 0.8))),  # from -x
])
def test_the_layer_nearest_the_viewer_is_drawn_over_the_other(tmp_path, view, near, far):
    rec = two_layers(far, near)  # body 0 far, body 1 near, the same square in the picture
    img = pixels(render_frames(rec, tmp_path / view, view=view)[0])
    seen_far, seen_near = mask(img, PALETTE[0]).sum(), mask(img, PALETTE[1]).sum()
    assert seen_near > 5000 and seen_far < 0.05 * seen_near, (seen_near, seen_far)


def test_the_rerun_recording_outlines_each_region_at_every_frame(tmp_path):
    """/regions/<name> in the Rerun recording: at each particle frame the
    region's outline where its particles are (a box moving at 0.1 m/s until
    t = 1 s), opaque magenta while it acts and faint after; a region that
    never moves, once and static; in the 2D view's y-flip with the other
    spatial entities."""
    from rerun.chunk import RrdReader

    from pipelines.recording import layout
    from pipelines.recording.rerun_sink import RerunSink
    from pipelines.recording.sinks import RunMeta

    region = dict(CLAMP, velocity=[0.1, 0.0], end=1.0)
    still = dict(CLAMP, name="anchor")  # never moves nor lets go: logged once, static
    config = {"scene": {"dim": 2, "domain": [1.2, 0.9], "regions": [region, still]}}
    path = tmp_path / "recording.rrd"
    sink = RerunSink(path, threaded=False)
    x = slab((0.15, 0.65), (0.3, 0.75)).astype(np.float32)
    sink.start(RunMeta(name="regions", dim=2, domain=(1.2, 0.9), wall_cells=3, dx=0.05, body_names=["beam"],
                       particle_body=np.zeros(len(x), np.int64), particle_radius=0.005,
                       properties={"config": {"yaml": yaml.safe_dump(config)}}))
    times = (0.0, 0.5, 1.5)
    for step, t in enumerate(times):
        sink.particles(step, t, x, None)
    sink.close()
    df = RrdReader(str(path)).stream().collect().reader(index="step", contents="/regions/**").to_pandas()
    strips = df["/regions/clamp:LineStrips2D:strips"].tolist()
    colors = df["/regions/clamp:LineStrips2D:colors"].tolist()
    reg, anchor = regions.of_config(config)
    assert anchor.still and not reg.still
    static = RrdReader(str(path)).stream().collect().reader(index=None, contents="/regions/**").to_pandas()
    assert not any(c.startswith("/regions/clamp") for c in static.columns)  # the moving one: per frame
    assert np.allclose(np.stack(static["/regions/anchor:LineStrips2D:strips"].iloc[0][0]), anchor.outline(0.0, 2)[0])
    for t, got, color in zip(times, strips, colors):
        want = reg.outline(t, 2)[0]
        assert np.allclose(np.stack(got[0]), want, atol=1e-6)
        alpha = int(color[0]) & 0xFF
        assert alpha == (255 if t < 1.0 else regions.EDGE_IDLE_RGBA[3])
    assert np.allclose(np.stack(strips[-1][0]).min(0), [0.15 + 0.1, 0.64], atol=1e-6)  # stopped at its end
    assert "regions" in layout.declared(path)["flip"]
