"""The pipelines around the MPM solver: configuration, runs, recording, sweeps, benchmarks and reports."""
