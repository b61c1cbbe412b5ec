"""The sections of the sweep report, one module per analysis."""
