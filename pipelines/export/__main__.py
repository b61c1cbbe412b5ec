"""``python -m pipelines.export``: see :mod:`pipelines.export.command`."""

import sys

from .command import main

if __name__ == "__main__":
    sys.exit(main())
