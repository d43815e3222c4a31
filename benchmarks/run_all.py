"""Run every benchmark in this folder (bench_*.py), one after the other, each in its own process.

    python benchmarks/run_all.py [--only NAME ...] [--list]

Each benchmark runs with its default arguments in a fresh interpreter (so one benchmark's numba
threads, caches or memory do not colour the next) and prints its own figures. The exit status is
non-zero if any benchmark failed. Nothing is asserted about the figures.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def benchmarks() -> list[Path]:
    return sorted(HERE.glob("bench_*.py"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="+", metavar="NAME", help="run only these (e.g. elements submesh)")
    p.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    args = p.parse_args(argv)
    scripts = benchmarks()
    if args.only:
        wanted = {n.removeprefix("bench_").removesuffix(".py") for n in args.only}
        scripts = [s for s in scripts if s.stem.removeprefix("bench_") in wanted]
        missing = wanted - {s.stem.removeprefix("bench_") for s in scripts}
        if missing:
            p.error(f"no benchmark named {sorted(missing)}; have {[s.stem for s in benchmarks()]}")
    if args.list:
        print("\n".join(s.name for s in scripts))
        return 0
    failed = []
    t_all = time.perf_counter()
    for script in scripts:
        print(f"\n{'=' * 100}\n{script.name}\n{'=' * 100}", flush=True)
        t = time.perf_counter()
        rc = subprocess.call([sys.executable, str(script)])
        print(f"--- {script.name}: {'ok' if rc == 0 else f'FAILED (exit {rc})'} in {time.perf_counter() - t:.1f} s", flush=True)
        if rc != 0:
            failed.append(script.name)
    print(f"\n{len(scripts)} benchmarks in {time.perf_counter() - t_all:.1f} s" + (f", failed: {failed}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
