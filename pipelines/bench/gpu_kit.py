"""A GPU session in two short calls: what a bare GPU machine needs to run
the CUDA tests and the GPU tables, packed here, unpacked and run there.

    python -m pipelines.bench.gpu_kit pack                 # here: .gpu/a and .gpu/b, each under 60 MiB
    python -m pipelines.bench.gpu_kit unpack               # there, in the checkout's root: /tmp/gpu-site
    python -m pipelines.bench.gpu_kit session --out DIR    # there: the CUDA tests and the tables, logs in DIR
    python -m pipelines.bench.gpu_kit session --quick --out DIR   # the re-measurement after a change

A GPU machine that starts bare, reached over a transfer of at most 64 MiB
per call, lacks warp-lang (its wheel is 149 MB; its CUDA library alone,
warp/bin/warp.so, 285 MB, 81 MB as xz) and the pure-Python packages of
the configuration (hydra-core, omegaconf, antlr4). ``pack`` writes
warp-lang's Python sources without its CPU compiler (warp-clang.so) and
the configuration's packages as one tar (site.tar.xz) with the first half
of warp.so.xz into ``.gpu/a``, and the second half into ``.gpu/b``. A
first call carries ``.gpu/a`` and copies it to /tmp/gpu-kit; a second call
straight after (the machine stays warm for seconds only) carries
``.gpu/b``, ``unpack`` joins the halves, checks warp.so's SHA-256 and
unpacks everything to /tmp/gpu-site, and ``session`` runs with
PYTHONPATH=/tmp/gpu-site:

- full (the default): the machine (nvidia-smi, versions), ``pytest
  tests/mpm`` on CUDA (the tests not marked slow) on 16 workers, then the tables
  ``gpu-profile`` (per kernel) and ``large`` (1M and 10M particles, the
  CUDA graph) without recordings (no rerun-sdk there), each step under
  its own time limit so that the whole stays inside one call's 10 minutes;
- ``--quick``: the two tables only.

Each step's output goes to DIR (``session.log`` and the tables' JSON),
what comes back from the machine. ``.gpu/`` is ignored (.gitignore).
"""

from __future__ import annotations

import argparse
import hashlib
import lzma
import os
import shutil
import subprocess
import sys
import tarfile
import time
from pathlib import Path

PACKAGES = ("warp", "hydra", "omegaconf", "antlr4")  # the Python packages site.tar.xz holds
LEFT_OUT = ("bin/warp-clang.so", "bin/warp.so", "tests", "examples")  # warp's parts a GPU run needs not
SITE = Path("/tmp/gpu-site")
KIT = Path("/tmp/gpu-kit")
# (name, command, time limit [s]) of a session; {py} is the Python that runs it
FULL = (
    ("machine", "nvidia-smi; {py} -c 'import warp, numpy, sys; warp.init(); print(sys.version, numpy.__version__)'",
     30),
    ("tests on CUDA", "{py} -m pytest tests/mpm --device cuda -n 16 -q -p no:cacheprovider -m 'not slow'", 200),
    ("gpu-profile", "{py} -m pipelines.bench --only gpu-profile --no-recording --device cuda "
     "--json {out}/gpu_profile.json", 180),
    ("large", "{py} -m pipelines.bench --only large --no-recording --device cuda --json {out}/large.json", 150),
)
QUICK = tuple(s for s in FULL if s[0] in ("large", "gpu-profile"))


def _site_packages() -> Path:
    import warp

    return Path(warp.__file__).resolve().parent.parent


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def pack(kit: Path, site: Path | None = None) -> list[Path]:
    """Write kit/a (site.tar.xz, warp.so.xz.0, warp.so.sha256) and kit/b
    (warp.so.xz.1) from the packages in ``site`` (default: this
    environment's); the files written."""
    site = site or _site_packages()
    shutil.rmtree(kit, ignore_errors=True)
    (kit / "a").mkdir(parents=True)
    (kit / "b").mkdir(parents=True)
    warp_dir = site / "warp"

    def keep(info: tarfile.TarInfo):
        rel = Path(info.name).relative_to("warp") if info.name.startswith("warp/") else None
        if rel is not None and any(str(rel) == x or str(rel).startswith(x + "/") for x in LEFT_OUT):
            return None
        return None if "__pycache__" in info.name else info

    with tarfile.open(kit / "a" / "site.tar.xz", "w:xz") as tar:
        for name in PACKAGES:
            tar.add(site / name, arcname=name, filter=keep)
    so = warp_dir / "bin" / "warp.so"
    (kit / "a" / "warp.so.sha256").write_text(_sha256(so) + "\n")
    data = lzma.compress(so.read_bytes(), preset=6)
    half = len(data) // 2
    (kit / "a" / "warp.so.xz.0").write_bytes(data[:half])
    (kit / "b" / "warp.so.xz.1").write_bytes(data[half:])
    return sorted(p for p in kit.rglob("*") if p.is_file())


def unpack(kit: Path, parts: Path, site: Path) -> Path:
    """Join the halves found in ``kit`` or ``parts`` (a/ and b/), check
    warp.so against its SHA-256 and unpack it with site.tar.xz into ``site``."""

    def find(name: str) -> Path:
        for p in (parts / "a" / name, parts / "b" / name, kit / name):
            if p.exists():
                return p
        raise SystemExit(f"gpu_kit unpack: {name} not found in {parts}/a, {parts}/b or {kit}")

    shutil.rmtree(site, ignore_errors=True)
    site.mkdir(parents=True)
    with tarfile.open(find("site.tar.xz")) as tar:
        tar.extractall(site, filter="data")
    so = site / "warp" / "bin" / "warp.so"
    so.parent.mkdir(parents=True, exist_ok=True)
    so.write_bytes(lzma.decompress(find("warp.so.xz.0").read_bytes() + find("warp.so.xz.1").read_bytes()))
    want = find("warp.so.sha256").read_text().strip()
    if _sha256(so) != want:
        raise SystemExit(f"gpu_kit unpack: warp.so's SHA-256 differs from the packed one ({want[:12]}...)")
    return site


def keep_first_half(parts: Path, kit: Path) -> None:
    """The first call's work there: copy ``parts``/a to ``kit`` (kept while the machine stays warm)."""
    kit.mkdir(parents=True, exist_ok=True)
    for p in (parts / "a").iterdir():
        shutil.copy2(p, kit / p.name)


def session(out: Path, quick: bool, site: Path, py: str = sys.executable, steps=None) -> int:
    """Run the session's ``steps`` (default FULL, or QUICK), each under its
    time limit, with ``site`` first on PYTHONPATH; their output to
    out/session.log. Returns the number of steps that failed or ran out of
    time."""
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.getcwd()]), PYTHONUNBUFFERED="1",
               MPM_DEVICE="cuda")
    failed = 0
    with open(out / "session.log", "a") as log:
        for name, command, limit in steps or (QUICK if quick else FULL):
            cmd = command.format(py=py, out=out)
            log.write(f"\n=== {name}: {cmd} (limit {limit} s)\n")
            log.flush()
            t0 = time.perf_counter()
            try:
                rc = subprocess.run(cmd, shell=True, env=env, stdout=log, stderr=subprocess.STDOUT,
                                    timeout=limit).returncode
            except subprocess.TimeoutExpired:
                rc = "timed out"
            took = time.perf_counter() - t0
            log.write(f"=== {name}: {rc} after {took:.0f} s\n")
            log.flush()
            print(f"{name}: {rc} after {took:.0f} s", flush=True)
            failed += rc != 0
    return failed


VERBS = ("pack", "keep", "unpack", "session")


def main(argv=None) -> int:
    from ..config.arguments import Parser, output_dir

    p = Parser(prog="python -m pipelines.bench.gpu_kit", description=__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("verb", choices=VERBS, help="pack (here), keep (there, first call), unpack (there, second "
                   "call), session (there)")
    p.add_argument("--dir", type=Path, default=Path(".gpu"), help="the halves' folder (default: .gpu)")
    p.add_argument("--out", type=Path, default=None, help="session: the folder of its log and tables")
    p.add_argument("--quick", action="store_true", help="session: the two tables only")
    args = p.parse_args(argv)
    if args.verb == "pack":
        if problem := output_dir("--dir", args.dir):
            p.error(problem)
    elif args.verb in ("keep", "unpack") and not args.dir.is_dir():
        p.error(f"--dir: {args.dir} is not a directory; accepted: the folder pack wrote (.gpu)")
    if args.out is not None and (problem := output_dir("--out", args.out)):
        p.error(problem)
    if args.verb == "session" and args.out is None:
        p.error("--out: missing for session; accepted: a folder to write the session's log and tables into")
    if args.verb == "pack":
        for f in pack(args.dir):
            print(f"{f}  {f.stat().st_size / 2**20:.1f} MiB")
        return 0
    if args.verb == "keep":
        keep_first_half(args.dir, KIT)
        return 0
    if args.verb == "unpack":
        print(unpack(KIT, args.dir, SITE))
        return 0
    assert args.out is not None  # refused above
    return min(session(args.out, args.quick, SITE), 125)


if __name__ == "__main__":
    sys.exit(main())
