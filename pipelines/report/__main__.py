"""``python -m pipelines.report <sweep dir> [--out DIR]``: the sweep report."""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
