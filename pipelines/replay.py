"""``python -m pipelines.replay <recording.rrd | run dir> [options]``: replay,
render, reproduce or repair a recording (:mod:`pipelines.recording.replay`)."""

import sys

from .recording.replay import main

if __name__ == "__main__":
    sys.exit(main())
