"""``python -m pipelines.granular <run dir> ...``: the deposit of finished
column-collapse runs beside the published scaling
(:mod:`pipelines.report.sections.granular`)."""

from .report.sections.granular import main

if __name__ == "__main__":
    raise SystemExit(main())
