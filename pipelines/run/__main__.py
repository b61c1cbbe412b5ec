"""Command-line entry: ``python -m pipelines.run [overrides]``.

Hydra composes the config from ``conf/`` (groups scheme, kernel, material,
scene; settings run and log), the run is validated before anything is
compiled or allocated, and :func:`pipelines.run.runner.execute` writes
``recording.rrd`` and ``metrics.json`` into the Hydra run directory.

Exit codes: 0 completed, 1 failed (exception), 2 bad configuration,
3 unstable, 130 interrupted; a sweep (-m) exits with the worst of its jobs
(invalid 2, failed 1, interrupted 130, unstable 3) and prints a line with
the jobs per outcome and where the report is.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path
from typing import Any, cast

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from . import provenance
from ..config import plugins, schema
from ..config.errors import EXIT_CODES, EXIT_CONFIG, describe
from ..config.overrides import check_groups, check_stability_map, replace_inline_mappings
from ..config.validate import ConfigError, validate
from .warp_setup import init_warp

schema.register()
ENERGY_LOSS_NOTE = 0.25  # a run that lost more of its energy scale than this says so on its last line
_last_status: list[str] = []
_config_errors: list[str] = []


def run(cfg: DictConfig) -> dict:
    """Validate, run and return the metrics of one composed config. In a
    sweep, a job whose directory already holds a finished run of the same
    config hash returns that run's metrics instead, unless ``run.force``, and
    an unfinished one with a checkpoint continues from it; so does a run
    with ``run.resume`` true or null, unless it has finished."""
    hc = HydraConfig.get()
    out_dir = Path(hc.runtime.output_dir)
    try:
        experiment = hc.runtime.choices.get("experiment")
        if experiment and hc.mode != RunMode.MULTIRUN:  # its sweep would be ignored: one default job would run
            raise ConfigError("experiment", f"{experiment} is a sweep; accepted: run it with -m (python -m "
                                            f"pipelines.run -m +experiment={experiment})")
        plugins.prepare(list(hc.overrides.task))  # done by main(), but not in a launcher's worker process
        spec, warnings = validate(cfg, list(hc.overrides.task))
    except ConfigError as e:
        # said here too: a launcher's worker process never reaches main()
        print(f"error: {e}", file=sys.stderr)
        _config_errors.append(str(e))
        invalid = {"status": "invalid", "reason": str(e)}
        if hc.mode == RunMode.MULTIRUN:  # Hydra still writes into a job's directory: say why it is empty
            (out_dir / "metrics.json").write_text(json.dumps(invalid, indent=2) + "\n")
        else:
            _remove_if_empty(out_dir)
        return invalid
    for warning in warnings:
        print(f"warning: {warning}", file=sys.stderr)
    init_warp()  # a launcher's worker process did not pass through main()
    if cfg.run.plan:
        from .runner import plan

        print(plan(spec))
        _remove_if_empty(out_dir)
        return {"status": "plan", "reason": ""}
    overrides = list(hc.overrides.task)
    for note in unused_overrides(spec, overrides):
        print(f"note: {note}", file=sys.stderr)
    choices = effective_choices(cfg, {k: v for k, v in hc.runtime.choices.items() if not k.startswith("hydra")})
    origins = plugins.origins(spec.scene, spec.kernel)
    identity: dict[str, Any] = {"config_hash": provenance.config_hash(
        cast(dict, OmegaConf.to_container(cfg, resolve=True)), provenance.code_hash(),
        files={**spec.meshes, **plugins.sources(spec.scene, spec.kernel)})}
    if spec.meshes:
        identity["meshes"] = spec.meshes
    if origins:  # materials and kernels defined outside mpm: where
        identity["plugins"] = origins
    resume = None
    from .checkpoints import DIR, choose, listed

    sweep = hc.mode == RunMode.MULTIRUN and not cfg.run.force
    if sweep or cfg.run.resume is not False:  # a finished run is not continued: its record is kept
        done = finished(out_dir, identity["config_hash"])
        if done is not None:
            print(f"skipped: {out_dir} already holds this config's {done['status']} run "
                  f"(hash {identity['config_hash']}); run.force=true runs it again", file=sys.stderr)
            _last_status.append(done["status"])
            return done
    # the newest checkpoint that reads back, of this config and code (null, and a re-run sweep's unfinished
    # job: only where there is one)
    if cfg.run.resume or (cfg.run.resume is None or sweep) and listed(out_dir / DIR):
        try:
            resume, notes = choose(out_dir, identity)
        except ConfigError as e:
            if sweep and not cfg.run.resume:  # another config's job once held this directory: run anew
                print(f"note: {e}; {out_dir} runs from the start", file=sys.stderr)
                notes = []
            else:
                print(f"error: {e}", file=sys.stderr)
                _config_errors.append(str(e))
                return {"status": "invalid", "reason": str(e)}
        for note in notes:
            print(note, file=sys.stderr)
    if spec.stability_map is not None:  # a stability map: its points in this process
        from .stability_map import run_map

        metrics = run_map(spec, spec.stability_map, out_dir, identity)
    else:
        from .progress import Progress
        from .runner import execute  # with Rerun: imported only for a run that goes ahead

        if hc.mode != RunMode.MULTIRUN and Progress.shown(cfg.log.progress):
            print(f"run directory: {out_dir}", file=sys.stderr, flush=True)

        metrics = execute(spec, out_dir, OmegaConf.to_yaml(cfg, resolve=True), overrides, choices,
                          identity=identity, resume=resume)
    _last_status.append(metrics["status"])
    summary = (f"{metrics['status']}: {metrics['steps']} steps, t = {metrics['sim_time']:.4g} s, "
               f"{metrics.get('step_time_ms') or float('nan'):.3f} ms/step; {out_dir}")
    print(summary if not metrics["reason"] else f"{summary}\n{metrics['reason']}", file=sys.stderr)
    change = metrics.get("energy_change")
    if change is not None and change < -ENERGY_LOSS_NOTE:
        what, work = (("the energy of the material and the rigid bodies", "the boundaries' work (the bodies' "
                       "pushes on the material among it)") if metrics.get("rigid_bodies") else
                      ("the total energy", "the boundaries' work"))
        print(f"note: {what} fell by {-change:.2g} of its scale (metrics.json: energy_change), beyond "
              f"{work}: dissipated by the scheme, its transfers or contact", file=sys.stderr)
    return metrics


def unused_overrides(spec, overrides: list[str]) -> list[str]:
    """Overrides that the run cannot use, said rather than ignored: the
    material group when every body of the scene brings its own material, and
    ``kernel.flip`` (the blend of transfer=flip) with another transfer."""
    notes = []
    if not spec.material_used:
        mine = [o for o in overrides if o.lstrip("+~").split("=")[0].split(".")[0] == "material"]
        if mine:
            notes.append(f"{', '.join(mine)} has no effect: every body of scene {spec.scene_name} brings its own "
                         f"material (override scene.bodies.<i>.material.<key> instead)")
    flip = [o for o in overrides if o.lstrip("+~").split("=")[0] == "kernel.flip"]
    if flip and spec.transfer != "flip":
        notes.append(f"{', '.join(flip)} has no effect: it is the blend of kernel.transfer=flip, and this run's "
                     f"transfer is {spec.transfer} (add kernel.transfer=flip)")
    return notes


FINISHED = ("completed", "unstable")  # deterministic outcomes; failed and interrupted runs run again


def finished(job_dir: Path, config_hash: str) -> dict | None:
    """The metrics in ``job_dir`` if they belong to a finished run of this
    config hash. Only the job's own directory counts: job numbers shift when a
    sweep's parameter list changes, and another directory's run would then be
    overwritten by the job that owns it."""
    try:
        metrics = json.loads((job_dir / "metrics.json").read_text())
    except (OSError, ValueError):
        return None
    if metrics.get("config_hash") == config_hash and metrics.get("status") in FINISHED:
        return metrics
    return None


def _remove_if_empty(run_dir: Path) -> None:
    """Drop the run directory Hydra made for a run that never started."""
    if run_dir.is_dir() and all(p.name in (".hydra", "run.log") for p in run_dir.iterdir()):
        shutil.rmtree(run_dir, ignore_errors=True)


NAMED_GROUPS = ("scene", "scheme", "kernel", "integrator")  # groups whose option is its ``name``


def effective_choices(cfg, choices: dict) -> dict:
    """Hydra's group choices with the option a ``<group>.name=...`` override
    switched to (it runs that option with its defaults, but Hydra records the
    group's choice): the record says what ran, and a note says so."""
    out = dict(choices)
    for group in NAMED_GROUPS:
        name = OmegaConf.select(cfg, f"{group}.name", default=None)
        alias = plugins.ALIASES.get(group, {}).get(str(out.get(group)))  # a dotted path chose it
        if group in out and name is not None and str(name) not in (str(out[group]), alias):
            print(f"note: {group}.name={name} set by key in the {group} option {out[group]}: the run and its "
                  f"record use {name} with its defaults ({group}={name} chooses it as the group)", file=sys.stderr)
            out[group] = str(name)
    return out


@hydra.main(version_base="1.3", config_path="../../conf", config_name="config")
def _main(cfg: DictConfig):
    return run(cfg)


def main() -> None:
    """Hydra's own error reports are multi-line; ask it to raise instead and
    print configuration errors on one line with exit code 2."""
    os.environ.setdefault("HYDRA_FULL_ERROR", "1")
    sys.argv[1:] = replace_inline_mappings(sys.argv[1:])
    init_warp()
    try:
        plugins.prepare(sys.argv[1:])  # MPM_PLUGINS and dotted paths: registered, then offered as options
        schema.register()
        check_groups(sys.argv[1:])
        check_stability_map(sys.argv[1:])
        _main()
    except KeyboardInterrupt:
        sys.exit(EXIT_CODES["interrupted"])
    except Exception as e:  # noqa: BLE001 - classified below
        message = describe(e)
        if message is None and isinstance(e, OSError) and e.filename and not _last_status:
            # Hydra could not create the run (or sweep) directory; a run that started fails with its traceback
            key = "hydra.sweep.dir" if any(a in ("-m", "--multirun") for a in sys.argv[1:]) else "hydra.run.dir"
            message = f"{key}: cannot create {e.filename}: {e.strerror}; accepted: a writable directory"
        if message is None:
            raise
        print(f"error: {message}", file=sys.stderr)
        _config_errors.append(message)
    if _config_errors:  # run() has printed its own
        sys.exit(EXIT_CONFIG)
    from .multiruns import SWEEPS

    if SWEEPS:  # a multirun: the worst outcome of any job (the summary line is printed)
        statuses = {s for outcome in SWEEPS for s in outcome}
        for status, code in SWEEP_EXIT:
            if status in statuses:
                sys.exit(code)
        return
    if _last_status and len(_last_status) == 1:
        sys.exit(EXIT_CODES.get(_last_status[0], 1))


# a sweep's exit code: the first status present among its jobs (0: all completed)
SWEEP_EXIT = [("invalid", EXIT_CONFIG), ("failed", 1), ("unreadable", 1), ("unknown", 1), ("killed", 1), ("running", 1),
              ("interrupted", EXIT_CODES["interrupted"]), ("preempted", EXIT_CODES["preempted"]),
              ("unstable", EXIT_CODES["unstable"])]


if __name__ == "__main__":
    main()
