"""The `vemdem` command line.

    vemdem run CONFIG.toml --out DIR     run the scenario a config describes
    vemdem example [NAME]                print an example config (no NAME: list them)
    vemdem status DIR [--json]           where a run in DIR stands (its stages too; or the runs in
                                         its subfolders), from checkpoints and summaries, without configs
    vemdem sweep CONFIG.toml --set KEY=V1,V2,... [--set ...] [--zip] --out DIR
                                         run one case per parameter set in parallel on Dask
                                         (a local cluster, or --scheduler ADDRESS); writes
                                         DIR/case_*/, DIR/sweep.csv and DIR/sweep.png (and a
                                         triaxial sweep over consolidation.stress, a direct shear
                                         sweep over normal.stress: envelope.png)

Exit status: 0 done, 2 bad config (one line naming the key), 1 the run failed (the message
names the cause; results written so far stay in DIR). A sweep exits 0 when some cases failed
(their errors are in sweep.csv) and 1 only when all of them did.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
import traceback
import warnings
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from . import sweep
from .config import ConfigError, load_toml
from .driver.checkpoint import CheckpointError, checkpoint_books
from .driver.loop import InitialStateError
from .scenarios.registry import (
    EXAMPLE_FILES,
    EXAMPLES,
    SCENARIOS,
    checked_config,
    example_line,
    example_text,
    write_example,
)

# what a run writes into --out: --overwrite removes these and nothing else
KNOWN_OUTPUTS = ("summary.json", "checkpoint.npz", "checkpoint.tmp.npz", "history.csv", "grains.csv", "walls.csv",
                 "fabric.csv", "fabric_rose.png", "fabric_first.npz",
                 "grains.pvd", "grains", "grain.pvd", "grain", "state.npz", "pile.png", "pile_3d.png", "pack_3d.png",
                 "force_strain.csv", "force_strain.png", "fluctuations.csv", "fluctuations.png",
                 "heap.png", "heap_3d.png", "tilt.png", "tilt_3d.png", "tilt.json", "pack",
                 "reequilibrate", "oedometer.csv", "oedometer.png", "fabric_rose_stages.png", "roses",
                 "triaxial.csv", "triaxial.png", "shear.csv", "shear.png")  # fmt: skip


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vemdem", description="Flexible polyhedral grains: VEM-DEM simulations")
    p.add_argument("--version", action="version", version=f"vemdem {_version()}")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser(
        "run", help="run the scenario described by a TOML config",
        description=f"Run a scenario ({', '.join(SCENARIOS)}). `vemdem example` lists ready configs; "
                    "`vemdem example NAME > job.toml` writes one to start from.",
    )  # fmt: skip
    run.add_argument("config", type=Path)
    run.add_argument("--out", type=Path, required=True, help="output folder (created if missing)")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true",
                      help="continue an interrupted run from DIR/checkpoint.npz (the config may change only "
                           "solver.dt, dt_min, dt_max, max_iterations, easy_iterations, grow_after)")  # fmt: skip
    mode.add_argument("--overwrite", action="store_true", help="replace the results of an earlier run in DIR")
    ex = sub.add_parser("example", help="print an example config")
    ex.add_argument("name", nargs="?", help=f"one of: {', '.join(EXAMPLES)}")
    ex.add_argument("--dir", type=Path, metavar="DIR",
                    help="write DIR/NAME.toml and the files it names (an example's grain shapes) instead of "
                         "printing the config")  # fmt: skip
    st = sub.add_parser("status", help="where a run stands: time, steps, Newton iterations, from its checkpoint")
    st.add_argument("out", type=Path, metavar="DIR", help="the run's output folder (as given to run --out)")
    st.add_argument("--json", action="store_true", help="print the status as JSON")
    _add_sweep_parser(sub)
    return p


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _add_sweep_parser(sub) -> None:
    sw = sub.add_parser("sweep", help="run a config for several parameter values in parallel (Dask)")
    sw.add_argument("config", type=Path)
    sw.add_argument("--set", action="append", required=True, metavar="KEY=V1,V2,...",
                    help="a dotted config key and the values it takes (repeatable)")  # fmt: skip
    sw.add_argument("--zip", action="store_true", help="pair the --set lists element-wise instead of all combinations")
    sw.add_argument("--out", type=Path, required=True, metavar="DIR", help="output: a folder per case, sweep.csv")
    sw.add_argument("--scheduler", metavar="ADDRESS", help="use this running Dask cluster instead of a local one")
    sw.add_argument("--workers", type=_positive_int, default=os.cpu_count() or 1, metavar="N",
                    help="worker processes of the local cluster (default: number of CPU cores)")  # fmt: skip
    sw.add_argument("--dashboard", default=sweep.DASHBOARD, metavar="HOST:PORT",
                    help="the local cluster's dashboard address (default: this machine only; ':8787' opens it)")  # fmt: skip
    sw.add_argument("--plot-x", metavar="KEY", help="x of sweep.png (default: the last --set key)")
    sw.add_argument("--plot-y", metavar="KEY", help="y of sweep.png, a summary field (default: the headline result)")
    sw.add_argument("--quiet", action="store_true", help="no progress output")


def _progress_bar(quiet: bool):
    if quiet:
        return None
    from tqdm import tqdm

    bar = {}

    def update(done: int, total: int, text: str = ""):
        if "bar" not in bar or bar["bar"].total != total or done < bar["bar"].n:  # a new stage
            if "bar" in bar:
                bar["bar"].close()
            bar["bar"] = tqdm(total=total, file=sys.stderr, dynamic_ncols=True, leave=True)
        b = bar["bar"]
        moved = done - b.n
        b.update(moved)
        if text:  # a line inside a frame (no count to move the bar) is drawn at once
            b.set_postfix_str(text, refresh=moved == 0)
        if done >= total:
            b.close()

    return update


def _version() -> str:
    try:
        return version("vemdem")
    except PackageNotFoundError:
        return "unknown"


# --overwrite moves the earlier run's outputs here first and removes them only once the new run is
# under way: a config mistake that the scenario finds (a missing grain file) gives them back
REPLACED = ".vemdem-replaced"


def _prepare_out(out: Path, resume: bool, overwrite: bool) -> bool:
    """Check --out (and, with --overwrite, move the earlier run's outputs aside into REPLACED);
    True when this run creates the folder."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out: {out} is a file, not a folder")
    used = [name for name in KNOWN_OUTPUTS if (out / name).exists()] if out.is_dir() else []
    if used and not (resume or overwrite):
        raise ConfigError(f"--out: {out} holds the results of another run ({', '.join(used[:3])}); "
                          "use --resume to continue it, --overwrite to replace it, or another folder")  # fmt: skip
    if overwrite and used:
        aside = out / REPLACED
        shutil.rmtree(aside, ignore_errors=True)
        aside.mkdir()
        for name in used:
            (out / name).rename(aside / name)
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".vemdem-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ConfigError(f"--out: cannot write to {out} ({exc.strerror or exc})") from None
    return created


def _remove_if_empty(out: Path, created: bool) -> None:
    if created and out.is_dir() and not any(out.iterdir()):
        out.rmdir()


def _settle_replaced(out: Path, restore: bool) -> None:
    """The earlier run's outputs that --overwrite moved aside: back in place where the new run
    stopped on its input (whatever it wrote removed first), removed otherwise."""
    aside = out / REPLACED
    if not aside.is_dir():
        return
    if restore:
        for name in KNOWN_OUTPUTS:
            target = out / name
            if target.is_dir():
                shutil.rmtree(target)
            else:
                target.unlink(missing_ok=True)
        for item in aside.iterdir():
            item.rename(out / item.name)
        aside.rmdir()
    else:
        shutil.rmtree(aside, ignore_errors=True)


COMPILE_NOTICE = "vemdem: compiling the numerical kernels (once per install, about {minutes}) ..."
COMPILE_MINUTES = "a minute or two"  # 76 s of CPU for the main job's kernels on a 2-core VM (README)


def _compile_notice(quiet: bool):
    """A context in which the first kernel numba really compiles says so, once: numba announces a
    compile (its "numba:compile" event) only when its cache has no kernel for these sources and
    this CPU target, so a cached install says nothing, and a mistake found before the first kernel
    runs (a missing grain file) is answered in its own line, not after a promise of minutes."""
    from contextlib import nullcontext

    if quiet:
        return nullcontext()
    from numba.core import event

    class Notice(event.Listener):
        said = False

        def on_start(self, _event):
            if not self.said:
                self.said = True
                from tqdm import tqdm

                tqdm.write(COMPILE_NOTICE.format(minutes=COMPILE_MINUTES), file=sys.stderr)  # above a progress bar

        def on_end(self, _event):
            pass

    return event.install_listener("numba:compile", Notice())


# the errors that carry their own cause in words: vemdem's (TimeStepTooSmall names the last rejected
# step's cause) and the ValueError, RuntimeError and LinAlgError that vemdem raises with a message
_WORDED = (ValueError, RuntimeError)


def _is_bug(exc: BaseException) -> bool:
    """An error no input explains (a TypeError, an IndexError, ...): its traceback is what a report needs."""
    return not isinstance(exc, (*_WORDED, ArithmeticError, OSError, MemoryError)) and not _own(exc)


def _own(exc: BaseException) -> bool:
    return type(exc).__module__.split(".")[0] == "vemdem"


def _failure_text(exc: BaseException) -> str:
    """A failed run's cause in words: never a bare "OverflowError: (34, 'Numerical result out of
    range')", which names Python's complaint and not the run's."""
    name = type(exc).__name__
    if _own(exc) or isinstance(exc, _WORDED):
        return f"{name}: {exc}"
    if isinstance(exc, MemoryError):
        return "out of memory: fewer grains or fewer vertices per grain, or a machine with more memory"
    if isinstance(exc, OSError):
        return f"cannot read or write {exc.filename or 'a file'} ({exc.strerror or exc})"
    if isinstance(exc, ArithmeticError):
        return (f"a number overflowed or was divided by zero ({name}: {exc}): a config value far outside a grain "
                "run's that no bound caught, or a bug in vemdem; please report it with the config")  # fmt: skip
    return f"an internal error ({name}: {exc}), a bug in vemdem: please report it with the config and the traceback"


def cmd_run(args) -> int:
    try:
        cfg, module = checked_config(load_toml(args.config))
        if args.resume and not getattr(module, "RESUMABLE", False):
            raise ConfigError(f"--resume: {cfg['scenario']} runs cannot be resumed (they are short)")
        created = _prepare_out(args.out, args.resume, args.overwrite)
    except ConfigError as exc:
        print(f"vemdem: config error: {exc}", file=sys.stderr)
        return 2
    try:
        kwargs = {"resume": True} if args.resume else {}
        with _compile_notice(args.quiet):
            summary = module.run(cfg, args.out, base_dir=args.config.parent, progress=_progress_bar(args.quiet),
                                 **kwargs)  # fmt: skip
    except (ConfigError, CheckpointError, InitialStateError) as exc:
        _settle_replaced(args.out, restore=True)
        _remove_if_empty(args.out, created)
        print(f"vemdem: config error: {exc}", file=sys.stderr)
        if args.overwrite:
            print(f"vemdem: the earlier results in {args.out} are kept", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        _settle_replaced(args.out, restore=False)  # the new run has its checkpoint: it is the one to resume
        _remove_if_empty(args.out, created)
        print(f"\nvemdem: interrupted; continue from the last checkpoint with: vemdem run {args.config} --out {args.out} "
              "--resume", file=sys.stderr)  # fmt: skip
        return 130
    except Exception as exc:  # noqa: BLE001 - a started run's every failure is answered in words, exit status 1
        _settle_replaced(args.out, restore=False)
        _remove_if_empty(args.out, created)
        if _is_bug(exc):
            traceback.print_exc()
        print(f"vemdem: run failed: {_failure_text(exc)}", file=sys.stderr)
        print(f"vemdem: results written so far are in {args.out}", file=sys.stderr)
        return 1
    _settle_replaced(args.out, restore=False)
    if not args.quiet:
        headline = getattr(module, "headline", None)  # a scenario's measure in one line (pile_collapse: the angle)
        if headline is not None:
            print(f"{cfg['scenario']}: {headline(summary)}")
        print(f"{cfg['scenario']}: done in {summary['wall_seconds']:.1f} s; results in {args.out}")
    return 0


def cmd_example(args) -> int:
    if args.name is None:
        width = max(map(len, EXAMPLES))
        print("\n".join(f"{name:<{width}}  {example_line(name)}" for name in EXAMPLES))
        return 0
    try:
        if args.dir is None:
            sys.stdout.write(example_text(args.name))
            if EXAMPLE_FILES.get(args.name):
                print(f"vemdem: {args.name} names files beside it: `vemdem example {args.name} --dir DIR` writes "
                      "them with the config", file=sys.stderr)  # fmt: skip
            return 0
        written = write_example(args.name, args.dir)
        print(f"wrote {', '.join(str(p) for p in written)}; run: vemdem run {written[0]} --out "
              f"{args.dir / args.name}")  # fmt: skip
    except ConfigError as exc:
        print(f"vemdem: {exc}", file=sys.stderr)
        return 2
    return 0


def cmd_sweep(args) -> int:
    try:
        cases = sweep.plan_cases(load_toml(args.config), args.set, args.zip)
    except ConfigError as exc:
        print(f"vemdem: config error: {exc}", file=sys.stderr)
        return 2
    out = args.out.resolve()
    if out.exists() and not out.is_dir():
        print(f"vemdem: config error: --out: {out} is a file, not a folder", file=sys.stderr)
        return 2
    if (out / "sweep.csv").exists():  # its cases' folders would be written over one by one
        print(f"vemdem: config error: --out: {out} holds the results of another sweep (sweep.csv); use another folder",
              file=sys.stderr)  # fmt: skip
        return 2
    sweep.write_case_configs(cases, out, args.config.resolve().parent)
    try:
        results = sweep.run_cases(cases, out, args.config.resolve().parent, args.scheduler, args.workers, args.quiet,
                                  args.dashboard)  # fmt: skip
    except (OSError, ValueError) as exc:  # no scheduler at that address, or no such address
        print(f"vemdem: sweep failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    table = out / "sweep.csv"
    envelope = sweep.add_envelopes(cases, results, out / "envelope.png")
    sweep.write_table(table, cases, results)
    note = sweep.plot_sweep(out / "sweep.png", cases, results, args.zip, args.plot_x, args.plot_y)
    failed = sum(result["status"] != "ok" for result in results)
    if failed:
        print(f"vemdem: {failed} of {len(cases)} cases failed; their errors are in {table}", file=sys.stderr)
    if not args.quiet:
        print(note)
        if envelope:
            print(envelope)
        print(f"sweep: {len(cases)} cases, {len(cases) - failed} ok, {failed} failed; results in {table}")
    return 1 if failed == len(cases) else 0


# the stages a scenario runs into subfolders of its DIR before its own (scenarios.pack)
STAGE_FOLDERS = ("pack", "reequilibrate")


def run_status(folder: Path) -> dict | None:
    """One folder's status: its checkpoint's books (checkpoint_books) and, once finished, the summary's
    scenario and wall time; None for a folder that holds no run."""
    summary, checkpoint = folder / "summary.json", folder / "checkpoint.npz"
    if not (summary.is_file() or checkpoint.is_file()):
        return None
    status = {"folder": str(folder), "finished": summary.is_file()}
    if checkpoint.is_file():
        status.update(checkpoint_books(checkpoint), checkpoint_age_s=time.time() - checkpoint.stat().st_mtime)
    if summary.is_file():
        try:
            done = json.loads(summary.read_text())
        except (OSError, ValueError) as exc:
            raise CheckpointError(f"{summary} is not readable ({type(exc).__name__})") from None
        status.update(scenario=done.get("scenario"), wall_seconds=done.get("wall_seconds"),
                      wall_seconds_total=done.get("wall_seconds_total"))  # fmt: skip
        status.setdefault("time", done.get("simulated_time"))
        status.setdefault("n_steps", done.get("n_steps"))
    return status


def _status_line(s: dict) -> str:
    total = s.get("wall_seconds_total")
    if s["finished"]:
        wall = total if total is not None else s.get("wall_seconds") or 0.0
        head = f"{s['folder']}: finished ({s.get('scenario')}, {wall:.0f} s wall)"
    else:
        so_far = "" if total is None else f", {total / 60:.1f} min of wall time so far"
        head = f"{s['folder']}: not finished, checkpoint written {s['checkpoint_age_s'] / 60:.1f} min ago{so_far}"
    parts = [head]
    if s.get("time") is not None:
        parts.append(f"t = {s['time']:.6g} s" + (f" (frame {s['frame']})" if "frame" in s else ""))
    if "step" in s:
        causes = ", ".join(f"{k} {v:,}" for k, v in s["rejections"].items())
        parts.append(f"{s['n_steps']:,} steps, {s['n_rejected_steps']:,} rejected" + (f" ({causes})" if causes else ""))
        if s["n_newton_iterations"]:
            parts.append(f"{s['newton_iterations_per_step']:.1f} Newton it./step")
        parts.append(f"step {s['step']:.3g} s")
    lines = ["; ".join(parts)]
    for c in s.get("resume_changes", []):
        lines.append(f"  resumed at t = {c['time']:.6g} s with {c['key']} {c['then']} -> {c['now']}")
    return "\n".join(lines)


def _statuses(folder: Path) -> list[dict]:
    """The run in `folder` and its stages; for a folder that holds none itself, the runs in its
    subfolders (a sweep's case_*, bench_paper's runs)."""
    found = _statuses_here(folder)
    if found or not folder.is_dir():
        return found
    return [s for sub in sorted(p for p in folder.iterdir() if p.is_dir()) for s in _statuses_here(sub)]


def _statuses_here(folder: Path) -> list[dict]:
    return [s for s in map(run_status, (folder, *(folder / name for name in STAGE_FOLDERS))) if s is not None]


def cmd_status(args) -> int:
    try:
        found = _statuses(args.out)
        if found:
            text = json.dumps(found, indent=2) if args.json else "\n".join(_status_line(s) for s in found)
    except CheckpointError as exc:
        print(f"vemdem: status: {exc}", file=sys.stderr)
        return 2
    except (AttributeError, KeyError, TypeError, ValueError) as exc:  # a summary or checkpoint of the wrong shape
        print(f"vemdem: status: {args.out}: a damaged summary.json or checkpoint.npz ({type(exc).__name__}: {exc})",
              file=sys.stderr)  # fmt: skip
        return 2
    if not found:
        print(f"vemdem: status: {args.out} holds no run (no checkpoint.npz or summary.json, nor in its subfolders)",
              file=sys.stderr)  # fmt: skip
        return 2
    print(text)
    return 0


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings meant for the user, as the one line they are (no source location)."""
    print(f"vemdem: warning: {message}", file=file or sys.stderr)


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    warnings.showwarning = _one_line_warning
    return {"run": cmd_run, "example": cmd_example, "status": cmd_status, "sweep": cmd_sweep}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
