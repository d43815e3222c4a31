"""Parameter sweeps: one config, some of its values varied, every case run in parallel on Dask.

`--set KEY=V1,V2,...` names a dotted key of the TOML config and the values it takes. The cases
are the Cartesian product of the lists (the last key varies fastest), or with `--zip` the lists
paired element-wise. Every case config is checked against its scenario's schema before anything
runs, so a typo costs seconds, not a cluster's worth of half-finished runs.
"""

from __future__ import annotations

import copy
import csv
import itertools
import json
import os
import re
import shutil
import sys
import tomllib

import tomli_w
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .config import ConfigError
from .config.build import resolve_path
from .analysis.seeds import seed_statistics, varies
from .scenarios.registry import checked_config, pack_stage, scenario_module, settle_pack

Scalar = bool | int | float | str

# Cases run side by side, one per core: numba's own thread pool in each would oversubscribe them.
WORKER_ENV = {"NUMBA_NUM_THREADS": "1"}

_KEY = re.compile(r"[A-Za-z0-9_-]+(\.[A-Za-z0-9_-]+)*")
# One comma-separated field: quoted TOML strings may hold commas, anything else may not.
_FIELD = re.compile(r"""(?:"(?:[^"\\]|\\.)*"|'[^']*'|[^,"'])*""")
# Names and paths may go unquoted (`grain.shape=cube,random`); anything else must be valid TOML.
_BARE_WORD = re.compile(r"[\w.+\-/:~]+")
_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]")
MAX_NAME = 100
# Timings differ from run to run whatever the parameters: never the default thing to plot.
NOT_PLOTTED = {"wall_seconds"}
# The key of the random pack: a sweep over it is a set of repeats, summarised by mean and spread.
SEED = "seed"
PROGRESS_POLL = 2.0  # s between looks at the running cases' progress
PROGRESS_FILE = "progress.txt"  # a running case's last progress line, shown by the sweep's bar


@dataclass(frozen=True)
class Case:
    """One case of a sweep: its folder name, the swept values and its full config."""
    name: str  # folder name under the sweep's output folder
    params: dict[str, Scalar]  # swept key -> value, in the order the keys were given
    raw: dict  # the full config of this case, as `vemdem run` would read it


def parse_value(token: str, key: str) -> Scalar:
    """A TOML scalar (`0.9`, `true`, `"abc"`); a bare word that is not TOML is a string."""
    token = token.strip()
    if not token:
        raise ConfigError(f"--set {key}: empty value in the list")
    try:
        value = tomllib.loads(f"v = {token}")["v"]
    except tomllib.TOMLDecodeError:
        if not _BARE_WORD.fullmatch(token):
            raise ConfigError(f"--set {key}: {token} is not a TOML value (quote non-plain strings)") from None
        return token
    if not isinstance(value, (bool, int, float, str)):
        raise ConfigError(f"--set {key}: {token} is not a number, string or boolean")
    return value


def _split_fields(text: str, key: str) -> list[str]:
    fields, pos = [], 0
    while True:
        match = _FIELD.match(text, pos)
        fields.append(match.group())
        pos = match.end()
        if pos == len(text):
            return fields
        if text[pos] != ",":
            raise ConfigError(f"--set {key}: unbalanced quote in {text!r}")
        pos += 1


def parse_set(text: str) -> tuple[str, list[Scalar]]:
    """`KEY=V1,V2,...` -> (KEY, [V1, V2, ...])."""
    key, sep, values = text.partition("=")
    key = key.strip()
    if not sep:
        raise ConfigError(f"--set {text!r}: expected KEY=V1,V2,...")
    if not _KEY.fullmatch(key):
        raise ConfigError(f"--set {text!r}: {key!r} is not a dotted key such as contact.mu_s")
    if not values.strip():
        raise ConfigError(f"--set {key}: no values given")
    return key, [parse_value(field, key) for field in _split_fields(values, key)]


def parse_sets(texts: list[str]) -> dict[str, list[Scalar]]:
    """The `--set KEY=V1,V2,...` options as key -> values (a key given twice is an error)."""
    sweeps: dict[str, list[Scalar]] = {}
    for text in texts:
        key, values = parse_set(text)
        if key in sweeps:
            raise ConfigError(f"--set {key}: given twice")
        sweeps[key] = values
    return sweeps


def case_grid(sweeps: dict[str, list[Scalar]], zipped: bool) -> list[dict[str, Scalar]]:
    """The parameter sets of the cases, in case order. `seed` is never zipped: with --zip the other
    lists are paired and every pair runs with every seed (seed varying fastest)."""
    keys = list(sweeps)
    if zipped:
        paired = {k: v for k, v in sweeps.items() if k != SEED}
        lengths = {len(v) for v in paired.values()}
        if len(lengths) > 1:
            given = ", ".join(f"{k}: {len(v)}" for k, v in paired.items())
            raise ConfigError(f"--zip needs value lists of equal length, got {given}")
        seeds = sweeps.get(SEED, [None])
        grid = [{**dict(zip(paired, combo)), SEED: seed} for combo in zip(*paired.values()) for seed in seeds]
        return [{k: params[k] for k in keys} for params in grid]
    return [dict(zip(keys, combo)) for combo in itertools.product(*sweeps.values())]


def _slot(node: Any, part: str, key: str) -> tuple[dict | list, str | int]:
    """Where `part` of a dotted key lives in `node`: a table's key or an index into [[tables]]."""
    if isinstance(node, dict):
        return node, part
    if isinstance(node, list) and part.isdigit() and int(part) < len(node):
        return node, int(part)
    if isinstance(node, list):
        raise ConfigError(f"--set {key}: {part!r} is not an index of the {len(node)} tables there")
    raise ConfigError(f"--set {key}: {part!r} is below a value, not a table")


def seed_key(base: dict) -> str:
    """Where the config keeps the seed that `--set seed=...` sweeps: at the top (pack, scene) or in
    [pack] (the scenarios that settle a pack first). A config that starts from `initial_state` has
    no pack to seed: every seed would run the same case."""
    try:
        schema = scenario_module(base.get("scenario")).SCHEMA
    except ConfigError:
        return SEED  # the case check names the unknown scenario
    if SEED in schema or "seed" not in schema.get("pack", {}):
        return SEED
    if base.get("initial_state"):
        raise ConfigError("--set seed: this config starts from initial_state, so there is no pack for the seed to "
                          "make (every seed would run the same case); sweep the seed of the pack's config")  # fmt: skip
    return "pack.seed"


def with_values(base: dict, params: dict[str, Scalar]) -> dict:
    """A copy of the config with the swept keys set (`seed` goes where the scenario keeps its seed)."""
    raw = copy.deepcopy(base)
    for key, value in params.items():
        if key == SEED:
            key = seed_key(base)
        *parents, last = key.split(".")
        node: Any = raw
        for part in parents:
            container, slot = _slot(node, part, key)
            if isinstance(container, dict):
                container.setdefault(slot, {})
            node = container[slot]
        container, slot = _slot(node, last, key)
        container[slot] = value
    return raw


def _label(value: Scalar) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def case_name(index: int, n_cases: int, params: dict[str, Scalar]) -> str:
    """`case_000_mu_s=0.9_mu_d=0.8`: the index keeps names unique and sorted, the rest is for people."""
    width = max(3, len(str(n_cases - 1)))
    labels = [f"{key.rsplit('.', 1)[-1]}={_label(value)}" for key, value in params.items()]
    return _UNSAFE.sub("_", "_".join([f"case_{index:0{width}d}", *labels]))[:MAX_NAME]


def plan_cases(base: dict, set_args: list[str], zipped: bool) -> list[Case]:
    """All cases, each config checked: a ConfigError here means nothing should run."""
    grid = case_grid(parse_sets(set_args), zipped)
    cases = [Case(case_name(i, len(grid), params), params, with_values(base, params)) for i, params in enumerate(grid)]
    for case in cases:
        try:
            checked_config(case.raw)
        except ConfigError as exc:
            raise ConfigError(f"{case.name}: {exc}") from None
    return cases


def _absolute_paths(raw: dict, base_dir: Path) -> dict:
    """The config with every file it names made absolute (files are relative to the config file,
    and a case's config.toml lives in the case folder, not beside the base config)."""
    raw = json.loads(json.dumps(raw))
    base = Path(base_dir).resolve()

    def fix(table: dict, key: str):
        if isinstance(table, dict) and table.get(key):
            table[key] = str(resolve_path(table[key], base))

    fix(raw, "initial_state")
    fix(raw.get("grain", {}), "file")
    for grains in (raw.get("pack", {}).get("grains"), raw.get("grains")):
        if isinstance(grains, dict) and grains.get("files"):
            grains["files"] = [str(resolve_path(f, base)) for f in grains["files"]]
    for item in raw.get("grains", []) if isinstance(raw.get("grains"), list) else []:
        fix(item, "file")
    for item in raw.get("walls", []) if isinstance(raw.get("walls"), list) else []:
        fix(item, "file")
    return raw


def write_case_configs(cases: list[Case], out: Path, base_dir: Path = Path(".")) -> None:
    """Each case's config as TOML that `vemdem run` accepts (files named absolutely), written
    before anything runs, so even a case that dies with its worker can be re-run alone."""
    for case in cases:
        folder = out / case.name
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "config.toml").write_text(tomli_w.dumps(_absolute_paths(case.raw, base_dir)))


def flatten(summary: dict, prefix: str = "") -> dict[str, Scalar]:
    """The scalar fields of a summary, nested tables as `a.b`; lists and the like are left out."""
    flat: dict[str, Scalar] = {}
    for key, value in summary.items():
        if isinstance(value, np.generic):
            value = value.item()  # np.int64 is no int: make it one, so it is kept and prints plainly
        if isinstance(value, dict):
            flat.update(flatten(value, f"{prefix}{key}."))
        elif isinstance(value, (bool, int, float, str)):
            flat[f"{prefix}{key}"] = value
    return flat


def _failure(exc: BaseException) -> dict[str, str]:
    return {"status": "failed", "error": f"{type(exc).__name__}: {exc}"}


# ---------------------------------------------------------------------------- shared pack stages
PACK_FOLDER = "pack"  # where pile_collapse, lid_compression, ... keep their pack stage: DIR/pack


@dataclass(frozen=True)
class SharedPack:
    """A pack several cases settle the same way, settled once in the first case's folder."""
    folder: Path  # where it is settled: the pack folder of the first case that needs it
    config: dict  # the complete pack config (scenarios.pack.pack_config)
    cases: tuple[int, ...]  # the cases that start from it


def shared_packs(cases: list[Case], out: Path, base_dir: Path = Path(".")) -> list[SharedPack]:
    """Cases whose pack stages would settle the same pack (the same fingerprint: [pack] table,
    material, model, solver) share one, settled once. A sweep over the collapse's friction or the
    lid's speed then settles one pack per seed, not one per case; the pack is deterministic, so
    each case ends with the bits it would have alone."""
    groups: dict[str, list[int]] = {}
    configs: dict[str, dict] = {}
    for i, case in enumerate(cases):
        stage = pack_stage(_absolute_paths(case.raw, base_dir))  # files named as the case will name them
        if stage is not None:
            key, config = stage
            groups.setdefault(key, []).append(i)
            configs[key] = config
    return [SharedPack(out / cases[members[0]].name / PACK_FOLDER, configs[key], tuple(members))
            for key, members in groups.items() if len(members) > 1]  # fmt: skip


def run_pack(pack_config: dict, folder: str, case_folder: str) -> dict:
    """Settle a shared pack on a worker (progress shown as its first case's). Never raises."""
    report = _progress_file(Path(case_folder))
    try:
        settle_pack(pack_config, Path(folder), progress=report)
        report(0, 0, "pack settled, shared; the case waits for a worker")  # not the pack's last time
        return {"status": "ok"}
    except Exception as exc:  # noqa: BLE001 - every case of the pack reports it
        return _failure(exc)


def _link_or_copy(src: str, dst: str) -> None:
    try:
        os.link(src, dst)  # the pack's files are only read after it is settled
    except OSError:
        shutil.copy2(src, dst)


def adopt_pack(shared: Path, own: Path) -> None:
    """Put the shared pack where the case's scenario looks for its pack stage. A pack folder the
    case already has (a sweep re-run into the same DIR) is left for the scenario to judge: it
    reuses one made by the same pack config and refuses any other."""
    if shared.resolve() != own.resolve() and not own.exists():
        shutil.copytree(shared, own, copy_function=_link_or_copy)


def run_case(raw_config: dict, out_dir: str, base_dir: str, pack: dict | None = None,
             pack_folder: str | None = None) -> dict:  # fmt: skip
    """Run one case on a Dask worker (after its shared pack, if any, is settled). Never raises:
    one broken case must not end the sweep."""
    try:
        if pack is not None:
            if pack.get("status") != "ok":
                return {"status": "failed", "error": f"shared pack stage ({pack_folder}): {pack.get('error')}"}
            adopt_pack(Path(pack_folder), Path(out_dir) / PACK_FOLDER)
        cfg, module = checked_config(raw_config)
        summary = module.run(cfg, Path(out_dir), base_dir=Path(base_dir), progress=_progress_file(Path(out_dir)))
        return {**flatten(summary), "status": "ok"}
    except Exception as exc:  # noqa: BLE001 - whatever went wrong belongs in this case's row
        return _failure(exc)


def _progress_file(folder: Path):
    """A scenario's progress callback that keeps the case's last line in DIR/case/progress.txt,
    replaced atomically, where the sweep's own progress bar reads it (same file system)."""
    path, tmp = folder / PROGRESS_FILE, folder / (PROGRESS_FILE + ".tmp")

    def progress(i: int, n: int, text: str = "") -> None:
        try:
            tmp.write_text(f"{i}/{n} {text}".strip() if n else text)  # n = 0: a state, not a count
            tmp.replace(path)
        except OSError:
            pass  # progress is a courtesy: a full disk must fail the case where it writes results

    return progress


def running_line(out: Path, cases: list[Case], done: set[int]) -> str:
    """`case_003: 12/40 t = 0.06 s ...` for the running cases that have reported progress."""
    lines = []
    for i, case in enumerate(cases):
        path = out / case.name / PROGRESS_FILE
        if i not in done and path.exists():
            try:
                lines.append(f"{case.name.split('_')[1]}: {path.read_text()[:60]}")
            except OSError:
                continue
    return "; ".join(lines)


DASHBOARD = "127.0.0.1:8787"  # the local cluster's dashboard: this machine only, unless --dashboard says otherwise


@contextmanager
def dask_client(scheduler: str | None, workers: int, dashboard: str = DASHBOARD) -> Iterator[Any]:
    """A client of the given scheduler, or of a local cluster whose scheduler and dashboard listen
    on this machine only (`dashboard`: host:port; ":8787" opens it on every interface)."""
    # Imported here: `vemdem run` should not pay for importing Dask.
    from dask.distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    with (
        LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, env=WORKER_ENV, host="127.0.0.1",
                     dashboard_address=dashboard) as cluster,  # fmt: skip
        Client(cluster) as client,
    ):
        yield client


def _result(future) -> dict:
    """A case's result; a worker that died under it (out of memory, killed) makes it a failure."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 - Dask reports a lost worker with several exception types
        return _failure(exc)


def run_cases(
    cases: list[Case], out: Path, base_dir: Path, scheduler: str | None, workers: int, quiet: bool,
    dashboard: str = DASHBOARD,
) -> list[dict]:
    """Results in case order, whatever order the workers finish in."""
    from dask.distributed import wait
    from tqdm import tqdm

    results: list[dict] = [{} for _ in cases]
    with dask_client(scheduler, workers, dashboard) as client:
        # pure=False: a re-run on a shared cluster must run again, not reuse a cached result
        packs: dict[int, tuple] = {}
        for shared in shared_packs(cases, out, base_dir):
            future = client.submit(run_pack, shared.config, str(shared.folder), str(shared.folder.parent), pure=False)
            packs.update({i: (future, str(shared.folder)) for i in shared.cases})
        futures = [
            client.submit(run_case, case.raw, str(out / case.name), str(base_dir), *packs.get(i, ()), pure=False)
            for i, case in enumerate(cases)
        ]
        index = {future.key: i for i, future in enumerate(futures)}
        done: set[int] = set()
        with tqdm(total=len(cases), file=sys.stderr, disable=quiet, unit="case", dynamic_ncols=True) as bar:
            pending = set(futures)
            while pending:
                try:
                    finished, pending = wait(list(pending), timeout=None if quiet else PROGRESS_POLL,
                                             return_when="FIRST_COMPLETED")  # fmt: skip
                except TimeoutError:  # nothing finished yet: only the progress line to renew
                    finished = set()
                for future in finished:
                    i = index[future.key]
                    results[i] = _result(future)
                    done.add(i)
                    bar.update()
                if not quiet:
                    bar.set_postfix_str(running_line(out, cases, done), refresh=True)
    return results


def summary_columns(results: list[dict], taken: set[str]) -> list[str]:
    """The summary fields of the results, beyond the `taken` columns, sorted."""
    return sorted({key for result in results for key in result} - taken)


def seeded(cases: list[Case]) -> bool:
    """Whether the sweep repeats its cases over seeds (`--set seed=...`)."""
    return bool(cases) and SEED in cases[0].params


def _ok_rows(cases: list[Case], results: list[dict]) -> list[dict]:
    return [{**result, **case.params} for case, result in zip(cases, results) if result.get("status") == "ok"]


def seed_rows(cases: list[Case], results: list[dict]) -> list[dict]:
    """The `mean` and `std` rows of a sweep over seeds: one pair per setting of the other keys."""
    others = [k for k in cases[0].params if k != SEED]
    numeric = [{k: v for k, v in row.items() if k != SEED} for row in _ok_rows(cases, results)]
    rows = []
    for group in seed_statistics(numeric, others):
        for stat, values in (("mean", group.mean), ("std", group.std)):
            rows.append({**values, **group.setting, "case": stat, "status": stat, "n_seeds": group.n})
    return rows


def write_table(path: Path, cases: list[Case], results: list[dict]) -> None:
    """One row per case; a sweep over seeds adds a `mean` and a `std` row per setting of the other
    keys (their `seed` cell empty, `n_seeds` the successful seeds behind them)."""
    keys = list(cases[0].params)
    fixed = ["case", *keys, "status", "error"]
    extra = seed_rows(cases, results) if seeded(cases) else []
    header = fixed + summary_columns(results + extra, set(fixed))
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, header, lineterminator="\n")
        writer.writeheader()
        for case, result in zip(cases, results):
            writer.writerow({**result, "case": case.name, **case.params, "error": result.get("error", "")})
        writer.writerows(extra)


def envelope_of(cases: list[Case]) -> dict | None:
    """The scenario's ENVELOPE (scenarios.triaxial, scenarios.direct_shear), None for a scenario without one."""
    if not cases or not isinstance(cases[0].raw.get("scenario"), str):
        return None
    return getattr(scenario_module(cases[0].raw["scenario"]), "ENVELOPE", None)


def envelope_groups(cases: list[Case], results: list[dict]) -> tuple[str, dict[tuple, list[int]]] | None:
    """The cases whose failure states make one strength envelope: those of a sweep over the
    scenario's ENVELOPE key (a triaxial's confining stress, a shear box's normal stress) that share every other swept value,
    the seed included (one envelope per seed: the spread over seeds is the envelopes'). None where
    the scenario has no envelope or the sweep does not vary its key."""
    envelope = envelope_of(cases)
    key = envelope["key"] if envelope else None
    if key is None or key not in cases[0].params:
        return None
    others = [k for k in cases[0].params if k != key]
    groups: dict[tuple, list[int]] = {}
    for i, (case, result) in enumerate(zip(cases, results)):
        if result.get("status") == "ok":
            groups.setdefault(tuple(case.params[k] for k in others), []).append(i)
    return key, groups


def add_envelopes(cases: list[Case], results: list[dict], figure: Path) -> str | None:
    """Add each case's envelope (the scenario's `envelopes` of its group's summaries) to its
    result, and draw the envelopes, seeds pooled, into `figure`; a line saying what was done, or
    None where the sweep has no envelope."""
    grouped = envelope_groups(cases, results)
    if grouped is None:
        return None
    key, groups = grouped
    envelope = envelope_of(cases)
    for members in groups.values():
        fit = envelope["fit"]([results[i] for i in members])
        for i in members:
            results[i].update(fit)
    pooled: dict[tuple, list[int]] = {}
    names = [k for k in cases[0].params if k != key]
    for setting, members in groups.items():
        pooled.setdefault(tuple(v for k, v in zip(names, setting) if k != SEED), []).extend(members)
    labels = [k for k in names if k != SEED]
    panels = []
    for setting, members in pooled.items():
        fit = envelope["fit"]([results[i] for i in members])
        if "envelope_phi_peak_deg" not in fit:
            continue
        title = ", ".join(f"{k}={_label(v)}" for k, v in zip(labels, setting)) or f"over {key}"
        panels.append(envelope["panel"](title, [results[i] for i in members], fit))
    if not panels:
        figure.unlink(missing_ok=True)
        return f"no envelope: no set of cases over {key} gave one (envelope_*_error in sweep.csv)"
    envelope["plot"](panels, figure)
    return f"envelope: {figure} (Mohr-Coulomb over {key}, {len(panels)} panel{'s' * (len(panels) > 1)})"


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def default_plot_y(scenario: str, ok: list[dict]) -> str | None:
    """The headline figure of a scenario, else the first numeric summary field (in the scenario's
    order) that the sweep changes by more than round-off; measured floats before integers, which
    are mostly counts."""
    if scenario == "pile_collapse" and any("angle_of_repose_deg" in r for r in ok):
        return "angle_of_repose_deg"
    varying = []
    for key in ok[0] if ok else []:
        values = [r[key] for r in ok if key in r]
        if key not in NOT_PLOTTED and all(_is_number(v) for v in values) and varies(values):
            varying.append((all(isinstance(v, int) for v in values), key))
    return min(varying, key=lambda item: item[0])[1] if varying else None


def _default_x(keys: list[str]) -> str:
    """The last swept key, the seed only when nothing else is swept (seeds are repeats, not a trend)."""
    return next((k for k in reversed(keys) if k != SEED), keys[-1])


def plot_sweep(
    path: Path, cases: list[Case], results: list[dict], zipped: bool, x: str | None = None, y: str | None = None
) -> str:
    """Plot y against x for the cases that ran; returns a line saying what was drawn, or why not.
    Over seeds: each seed a faint dot, their mean with a one-standard-deviation bar."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    keys = list(cases[0].params)
    x = x or _default_x(keys)
    rows = _ok_rows(cases, results)
    y = y or default_plot_y(str(cases[0].raw.get("scenario", "")), [r for r in rows])
    rows = [r for r in rows if y and _is_number(r.get(x)) and _is_number(r.get(y))]
    if not rows:
        path.unlink(missing_ok=True)  # a plot left by an earlier sweep in DIR would pass for this one's
        return f"no plot: no successful case has numeric values of {x} and {y or 'a varying summary field'}"
    over_seeds = SEED in keys and x != SEED
    # A product sweep is a family of curves, one per setting of the other swept keys; in a zipped
    # sweep all keys but the seed move together, so it is one curve.
    others = [k for k in keys if k not in (x, SEED)] if not zipped and x in keys else []
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in others), []).append(row)
    fig = Figure(figsize=(6, 4.2), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for group, members in groups.items():
        label = ", ".join(f"{k}={_label(v)}" for k, v in zip(others, group)) or None
        if over_seeds:
            _plot_seed_means(ax, members, x, y, label)
        else:
            members.sort(key=lambda r: r[x])
            ax.plot([r[x] for r in members], [r[y] for r in members], "o-", ms=4, label=label)
    if x == SEED and len(rows) > 1:
        _mean_band(ax, [r[y] for r in rows])
    _no_round_off_trend(ax, [r[y] for r in rows])
    ax.set_xlabel(x)
    ax.set_ylabel(f"{y} (mean and std over seeds)" if over_seeds else y)
    ax.grid(alpha=0.3)
    if others or x == SEED:
        ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path)
    return f"plot: {path} ({y} against {x}{', mean and spread over seeds' if over_seeds else ''})"


def _plot_seed_means(ax, members: list[dict], x: str, y: str, label: str | None) -> None:
    at = sorted({r[x] for r in members})
    ys = [np.array([r[y] for r in members if r[x] == xv], dtype=float) for xv in at]
    line = ax.errorbar(at, [v.mean() for v in ys], yerr=[v.std(ddof=1) if v.size > 1 else 0.0 for v in ys],
                       fmt="o-", ms=5, capsize=3, label=label)  # fmt: skip
    colour = line.lines[0].get_color()
    ax.plot([r[x] for r in members], [r[y] for r in members], ".", color=colour, alpha=0.35, ms=5)


def _mean_band(ax, values: list[float]) -> None:
    v = np.asarray(values, dtype=float)
    mean, std = v.mean(), v.std(ddof=1)
    ax.axhline(mean, color="k", lw=1, label=f"mean {mean:.4g} +- {std:.2g} (std)")
    ax.axhspan(mean - std, mean + std, color="k", alpha=0.1)


def _no_round_off_trend(ax, values: list[float]) -> None:
    """Values equal up to round-off are one value: show them on a flat axis around it, not on an
    axis of width 1e-18 that draws the round-off as a trend."""
    if not varies(values):
        centre = float(np.mean(values))
        half = 0.05 * abs(centre) or 1.0
        ax.set_ylim(centre - half, centre + half)
    ax.ticklabel_format(axis="y", useOffset=False)
