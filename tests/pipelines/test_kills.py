"""Runs killed with SIGKILL (pipelines.kills): a real process killed twice,
once at a random moment and once inside a checkpoint write, each time
started again with ``run.resume=null``, ends bit for bit as the run that was
never stopped (final state, every scalar series, the particle frames, the
configuration-update events), its recording joined into one file and no
checkpoint's temporary file left."""

import numpy as np
import pytest

from pipelines import kills
from pipelines.run import checkpoints


@pytest.mark.slow
def test_a_run_killed_twice_once_inside_a_checkpoint_write_resumes_bit_for_bit(tmp_path, monkeypatch):
    monkeypatch.chdir(kills.Path(__file__).resolve().parents[2])
    monkeypatch.setitem(kills.CONFIGS, "aulmpm", [*kills.BALL, "scheme=aulmpm", "scheme.epsilon=0.01",
                                                  "scheme.eta=0.01", "run.steps=600"])
    ref, wall = kills.whole("aulmpm", tmp_path)
    counts, trials = kills.killed("aulmpm", tmp_path, kills=2, every=0.005, window=wall,
                                  rng=np.random.default_rng(1), aim=2)
    assert counts["kills"] == 2 and counts["aimed"] == 1 and counts["in_write"] >= 1, counts
    for trial in trials:
        same = kills.compare(ref, trial)
        assert all(same[k] for k in ("final_state", "scalars", "frames", "update_events", "one_file")), same
        assert same["updates"] > 0 and same["rows"] == 601, same
        assert not list((trial / checkpoints.DIR).glob(".ckpt-*.tmp"))
