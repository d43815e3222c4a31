"""The `vemdem` command line.

    vemdem run CONFIG.toml --out DIR     run the scenario a config describes
    vemdem example [NAME]                print an example config (no NAME: list them)

Exit status: 0 done, 2 bad config (one line naming the key), 1 the run failed (the message
names the cause; results written so far stay in DIR).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .config import ConfigError, load_toml
from .scenarios.registry import EXAMPLES, checked_config, example_text


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vemdem", description="Flexible polyhedral grains: VEM-DEM simulations")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run the scenario described by a TOML config")
    run.add_argument("config", type=Path)
    run.add_argument("--out", type=Path, required=True, help="output folder (created if missing)")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    run.add_argument("--resume", action="store_true", help="continue an interrupted run from DIR/checkpoint.npz")
    ex = sub.add_parser("example", help="print an example config")
    ex.add_argument("name", nargs="?", help=f"one of: {', '.join(EXAMPLES)}")
    return p


def _progress_bar(quiet: bool):
    if quiet:
        return None
    from tqdm import tqdm

    bar = {}

    def update(done: int, total: int, text: str = ""):
        if "bar" not in bar:
            bar["bar"] = tqdm(total=total, file=sys.stderr, dynamic_ncols=True, leave=True)
        b = bar["bar"]
        b.update(done - b.n)
        if text:
            b.set_postfix_str(text, refresh=False)
        if done >= total:
            b.close()

    return update


def cmd_run(args) -> int:
    try:
        cfg, module = checked_config(load_toml(args.config))
    except ConfigError as exc:
        print(f"vemdem: config error: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    try:
        kwargs = {"resume": True} if args.resume else {}
        summary = module.run(cfg, args.out, base_dir=args.config.parent, progress=_progress_bar(args.quiet), **kwargs)
    except ConfigError as exc:
        print(f"vemdem: config error: {exc}", file=sys.stderr)
        return 2
    except TypeError as exc:
        if args.resume and "resume" in str(exc):
            print(f"vemdem: {cfg['scenario']} runs cannot be resumed (they are short)", file=sys.stderr)
            return 2
        raise
    except (ArithmeticError, RuntimeError, ValueError, OSError) as exc:
        print(f"vemdem: run failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        print(f"vemdem: results written so far are in {args.out}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(f"{cfg['scenario']}: done in {summary['wall_seconds']:.1f} s; results in {args.out}")
    return 0


def cmd_example(args) -> int:
    if args.name is None:
        print("\n".join(EXAMPLES))
        return 0
    try:
        sys.stdout.write(example_text(args.name))
    except ConfigError as exc:
        print(f"vemdem: {exc}", file=sys.stderr)
        return 2
    return 0


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    return {"run": cmd_run, "example": cmd_example}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
