"""Run many ``python -m pipelines.run`` command lines in one process, for
the tests of one-line configuration errors (a process per command line costs
seconds of imports each): ``python cli_batch.py IN.json OUT.json`` with IN a
list of argument lists; OUT gets [exit code, stderr] per list."""

import contextlib
import io
import json
import os
import runpy
import sys
import traceback

# the working directory first on the path, as for ``python -m pipelines.run`` (run from the
# checkout's root: its pipelines, not an installed copy nor anything beside this script)
sys.path[0] = os.getcwd()

from hydra.core.global_hydra import GlobalHydra  # noqa: E402

from pipelines.run import multiruns  # noqa: E402


def one(args: list[str]) -> tuple[int, str]:
    """One command line, as ``python -m pipelines.run`` runs it (the module
    runs afresh as __main__: Hydra finds conf/ from its file)."""
    GlobalHydra.instance().clear()
    multiruns.SWEEPS.clear()
    sys.argv = ["pipelines/run/__main__.py", *args]
    err = io.StringIO()
    code = 0
    with contextlib.redirect_stderr(err):
        try:
            runpy.run_module("pipelines.run", run_name="__main__", alter_sys=True)
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except BaseException:  # noqa: BLE001 - an uncaught exception: exit 1 with its traceback
            traceback.print_exc()
            code = 1
    return code, err.getvalue()


if __name__ == "__main__":
    source, target = sys.argv[1:3]
    with open(source) as f:
        cases = json.load(f)
    results = [one(args) for args in cases]
    with open(target, "w") as f:
        json.dump(results, f)
