"""log.channels: besides /particles, one entity per field, /channels/<field>,
coloured by that field on its range (the run's own unless log.color_range
gives it), with its colour key, hidden in the blueprint (the user shows it
in the viewer); none by default."""

import numpy as np
import pytest
from rerun.chunk import RrdReader

from helpers import compose_cfg
from pipelines.config.validate import resolve
from pipelines.recording import layout
from pipelines.recording.colours import PALETTE_PACKED, colormap, values_range
from pipelines.recording.rerun_sink import RerunSink
from pipelines.recording.sinks import RunMeta
from pipelines.run.run_metrics import channel_ranges

N = 50


def record(path, dim: int, channels: dict, color: str = "body"):
    """Two frames of N particles with dJ, speed and plastic_strain (NaN on half of them)."""
    rng = np.random.default_rng(3)
    sink = RerunSink(path, threaded=False)
    sink.start(RunMeta(name="channels", dim=dim, domain=(1.0,) * dim, wall_cells=3, dx=0.05, body_names=["a", "b"],
                       particle_body=np.r_[np.zeros(N // 2), np.ones(N // 2)].astype(np.int64), particle_radius=0.01,
                       color=color, channels=channels))
    frames = []
    for step in (0, 5):
        x = rng.random((N, dim)).astype(np.float32)
        dJ = rng.random(N).astype(np.float32) * 0.2
        fields = {"speed": rng.random(N).astype(np.float32) * 3.0,
                  "plastic_strain": np.r_[np.full(N // 2, np.nan), rng.random(N // 2)].astype(np.float32)}
        sink.particles(step, 0.01 * step, x, dJ, fields)
        frames.append((x, dJ, fields))
    sink.close()
    return frames


def entity_colors(path, entity: str, dim: int) -> list[np.ndarray]:
    df = RrdReader(str(path)).stream().collect().reader(index="step", contents=entity).to_pandas()
    col = f"{entity}:Points{dim}D:colors"
    return [np.asarray(c, np.uint32) for c in df[col] if c is not None] if col in df.columns else []


@pytest.mark.parametrize("dim", [2, 3])
def test_each_channel_is_an_entity_coloured_on_its_range_and_hidden(tmp_path, dim):
    path = tmp_path / "recording.rrd"
    channels = {"speed": ((0.0, 2.5), "log.color_range"), "dJ": (None, ""), "plastic_strain": (None, "")}
    frames = record(path, dim, channels)
    ranges = {"speed": (0.0, 2.5), "dJ": values_range("dJ", [f[1] for f in frames]),
              "plastic_strain": values_range("plastic_strain", [f[2]["plastic_strain"] for f in frames])}
    assert ranges["dJ"][0] == 0.0 and ranges["dJ"][1] == max(float(f[1].max()) for f in frames)
    for name, (lo, hi) in ranges.items():
        got = entity_colors(path, f"/channels/{name}", dim)
        assert len(got) == 2, name
        for c, (x, dJ, fields) in zip(got, frames):
            values = dJ if name == "dJ" else fields[name]
            assert np.array_equal(c, colormap(values, hi, lo)), name
    # plastic_strain: grey where a particle has none
    assert np.all(entity_colors(path, "/channels/plastic_strain", dim)[0][:N // 2] == colormap(np.array([np.nan]), 1)[0])
    # the main entity keeps the body colours
    main = entity_colors(path, "/particles", dim)
    assert np.array_equal(main[0], PALETTE_PACKED[np.r_[np.zeros(N // 2), np.ones(N // 2)].astype(int)])
    d = layout.declared(path)
    assert sorted(d["hidden"]) == ["/channels/dJ", "/channels/plastic_strain", "/channels/speed"]
    if dim == 2:  # y up on the screen, like the particles
        assert d["flip"]["channels"] == layout.FLIP_2D
    props = RrdReader(str(path)).stream().collect().reader(index=None, contents="/__properties/**").to_pandas()
    assert list(props["property:channels:names"].iloc[0]) == ["speed", "dJ", "plastic_strain"]
    assert np.allclose(list(props["property:channels:high"].iloc[0]), [r[1] for r in ranges.values()])
    assert list(props["property:channels:source"].iloc[0]) == ["log.color_range", "the run's range", "the run's range"]
    # each channel's colour key beside the domain: a bar and its ends, the field and unit
    static = RrdReader(str(path)).stream().collect().reader(index=None, contents="/channels/**").to_pandas()
    labels = static[f"/channels/speed/key/labels:Points{dim}D:labels"].dropna().iloc[0]
    assert list(labels) == ["0", "2.5 m/s", "speed [m/s]"]


def test_no_channels_by_default(tmp_path):
    path = tmp_path / "recording.rrd"
    record(path, 2, {})
    assert layout.declared(path)["hidden"] == []
    static = RrdReader(str(path)).stream().collect().reader(index=None, contents="/**").to_arrow_table()
    assert not any(c.startswith("/channels") for c in static.column_names)
    assert resolve(compose_cfg([])).log.channels == []


def test_channels_are_declared_checked_and_ranged():
    """log.channels is a log option; a field the scene cannot record is
    refused naming the key; the ranges: log.color_range for the colouring
    field, else None (the run's own, found when it ends)."""
    spec = resolve(compose_cfg(["log.channels=[speed,dJ]", "log.color=dJ", "log.color_range=[0,0.2]"]))
    assert spec.log.channels == ["speed", "dJ"]
    with pytest.raises(ValueError, match=r"^log.channels: 'plastic_strain'; accepted: a list of dJ, speed"):
        resolve(compose_cfg(["log.channels=[plastic_strain]"]))
    r = channel_ranges(spec.log)
    assert r == {"dJ": ((0.0, 0.2), "log.color_range"), "speed": (None, "")}
    assert channel_ranges(resolve(compose_cfg([])).log) == {}


def test_the_size_estimate_counts_the_channels(tmp_path):
    """The recording-size estimate (log.size_warning_mb) grows with the
    channel entities by at least what they add to the file, and stays above
    the file's size (the default 2D scene, 20 steps, a frame every 2; the
    estimate leaves out Rerun's compression: measured 2.2x the file over 100
    steps, with or without channels)."""
    from pipelines.run.runner import execute

    sizes = {}
    for name, channels in (("none", "[]"), ("two", "[speed,dJ]")):
        spec = resolve(compose_cfg(["run.steps=20", "log.every=2", f"log.channels={channels}", "log.progress=false"]))
        m = execute(spec, tmp_path / name)
        assert m["status"] == "completed", m.get("reason")
        sizes[name] = (m["recording_estimate_mb"], (tmp_path / name / "recording.rrd").stat().st_size / 1e6)
    (est0, file0), (est2, file2) = sizes["none"], sizes["two"]
    assert file2 <= est2 and file0 <= est0
    assert file2 - file0 <= est2 - est0 <= 4.0 * (file2 - file0)
