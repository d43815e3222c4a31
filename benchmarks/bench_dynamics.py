"""Dynamics throughput: both integrators on settling packs of sand grains in a box
(docs/dynamics-benchmark.md).

    python benchmarks/bench_dynamics.py [--quick] [--grains 64,515,4096] [--integrator implicit|explicit|both]
                                        [--steps-implicit 20] [--steps-explicit 500] [--impact-steps 0,20]
                                        [--mass-scaling 1,1e4] [--budget 120] [--threads N]
                                        [--linear-solver default|scipy|pardiso] [--no-solver] [--profile]
                                        [--json PATH]

For each pack size N and integrator: steps per second, grain-steps per second, mean active contact
pairs, mean Newton iterations per step, mean time step and simulated time per wall second, measured
over a fixed number of accepted steps after one warm-up step (numba compilation and the first CSR
structure excluded). Integrators: implicit Newmark (beta 0.3025, gamma 0.6, dt_max 1e-4 s) without and
with the contact-impact step control (impact_steps 20), explicit central differences at the real
density and with mass scaling 1e4 (density factor, as `solver.mass_scaling`).

The pack (the paper's material: E = 90 GPa, nu = 0.16, rho = 2200 kg/m^3, grains of 1.45 mm +- 10 %,
mu_s 0.6, mu_d 0.5, floor and four walls): `column_packing(N, box=(L, L), clearance=0.05, seed=0)`
with L = 8 mm sqrt(N / 515), so that every pack settles to about the same height (about 16 grain
sizes, the paper's 515 grains in 8 mm). The column is then deposited geometrically, without dynamics:
from the lowest grain up, each grain is translated straight down until its convex hull comes within
0.95 activation gaps (vertically) of the floor or of a grain already deposited. The grains start at
rest, each resting on a point of the one below, in loose stacks that then slump: a settling pack
with contacts active from the first step, not a 0.15 s free fall of a 110 mm column.

Linear solver (with the implicit run of the pack nearest 515 grains): one Newton system of the real
pack, K = a1 M + K_int + K_contact as `newmark_step` assembles it at the last accepted state, solved
with SciPy's spsolve (SuperLU, `vemdem.solver.linear`'s fallback) and, if importable, pypardiso (its
default where installed; a fresh solver each time, so that no factorisation is reused). The share of
each implicit case's wall time spent in the integrator's own linear solves is measured too. Results
and their reading: docs/dynamics-benchmark.md. Nothing here asserts a timing.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import linprog
from scipy.spatial import ConvexHull

from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.pairs import GRAIN_A, GRAIN_B
from vemdem.contact.walls import box_walls
from vemdem.geometry import Polyhedron
from vemdem.geometry.packing import column_packing, pack_height, packing_fraction
from vemdem.model.scene import Scene
from vemdem.solver import newmark
from vemdem.solver.explicit import ExplicitIntegrator, advance_explicit, explicit_initial_state
from vemdem.solver.newmark import NewmarkParameters, advance, initial_state
from vemdem.solver.state import RunStats, StepControl, TimeStepTooSmall
from vemdem.vem.element import evaluate, tangent_matrix
from vemdem.vem.material import Material

SIZE = 1.45e-3
E, NU, DENSITY = 90e9, 0.16, 2200.0
MU_S, MU_D = 0.6, 0.5
GRAVITY = 9.81
REFERENCE_GRAINS, REFERENCE_SIDE = 515, 8e-3
DT_MAX = 1e-4
NEWMARK = NewmarkParameters(beta=0.3025, gamma=0.6)
DEPOSIT_GAP = 0.95  # in activation gaps: inside the layer (contacts active), but barely loaded


# ---------------------------------------------------------------------------- the pack
def box_side(n: int) -> float:
    """Side of the square box: the footprint grows with N, so the settled height stays the same."""
    return REFERENCE_SIDE * np.sqrt(n / REFERENCE_GRAINS)


def _vertical_clearance(upper: np.ndarray, lower: np.ndarray) -> float:
    """How far the convex hull `upper` can move straight down before it touches the hull `lower`
    (halfspaces n.x + d <= 0 of each); inf if their footprints do not overlap. A small LP in
    (x, y, z_upper, z_lower): minimise z_upper - z_lower over points of both on one vertical."""
    a = np.zeros((len(upper) + len(lower), 4))
    a[: len(upper), [0, 1, 2]] = upper[:, :3]
    a[len(upper) :, [0, 1, 3]] = lower[:, :3]
    b = -np.concatenate([upper[:, 3], lower[:, 3]])
    res = linprog([0.0, 0.0, 1.0, -1.0], A_ub=a, b_ub=b, bounds=[(None, None)] * 4, method="highs")
    return float(res.fun) if res.status == 0 else np.inf


def deposit(grains: list[Polyhedron], floor: float, gap: float) -> list[Polyhedron]:
    """Drop every grain straight down, lowest first, until its hull is `gap` (vertically) above the
    floor or a grain already dropped. Hulls are exact here (sand grains are convex), so no two grains
    overlap; their Euclidean gap is at most the vertical one, so every resting contact is active."""
    hulls = [ConvexHull(g.vertices).equations for g in grains]  # n.x + d <= 0 inside
    bottoms = np.array([g.vertices[:, 2].min() for g in grains])
    tops = np.array([g.vertices[:, 2].max() for g in grains])
    centres = np.array([g.centroid[:2] for g in grains])
    radii = np.array([np.linalg.norm(g.vertices[:, :2] - g.centroid[:2], axis=1).max() for g in grains])
    placed = np.zeros(len(grains), bool)
    drops = np.zeros(len(grains))
    for i in np.argsort(bottoms):
        drop = bottoms[i] - floor - gap
        near = placed & (np.hypot(*(centres - centres[i]).T) < radii + radii[i])
        # highest first: once a grain's top is below where this one would stop, none lower can stop it
        for j in sorted(np.flatnonzero(near), key=lambda j: -tops[j]):
            if tops[j] + gap <= bottoms[i] - drop:
                break
            drop = min(drop, _vertical_clearance(hulls[i], hulls[j]) - gap)
        drops[i] = max(drop, 0.0)
        hulls[i] = hulls[i] + np.outer(hulls[i][:, 2] * drops[i], [0.0, 0.0, 0.0, 1.0])  # d - n.t, t = -drop e_z
        bottoms[i] -= drops[i]
        tops[i] -= drops[i]
        placed[i] = True
    return [g.translated((0.0, 0.0, -d)) for g, d in zip(grains, drops)]


@dataclass
class Pack:
    n: int
    side: float
    grains: list[Polyhedron]
    size: float  # mean equivalent diameter (the contact laws' grain size)
    column_height: float  # as packed
    deposited_height: float  # twice the height of the centre of volume, after deposition
    deposited_fraction: float  # packing fraction below that height
    seconds: float


def make_pack(n: int) -> Pack:
    t = time.perf_counter()
    side = box_side(n)
    packing = column_packing(n, size=SIZE, box=(side, side), clearance=0.05, seed=0)
    size = float(np.mean(packing.sizes))
    law, _ = default_contact_laws(size, E, DENSITY, GRAVITY, MU_S, MU_D)
    grains = deposit(packing.grains, 0.0, DEPOSIT_GAP * law.activation_gap)
    height = pack_height(grains)
    fraction = packing_fraction(grains, (side, side), height)
    return Pack(n, side, grains, size, packing.column_height, height, fraction, time.perf_counter() - t)


def make_scene(pack: Pack, mass_scaling: float = 1.0) -> Scene:
    """Mass scaling multiplies the density, and with it the weight and the contact laws' force scale
    (as the `scene` scenario does): the rigid-grain motion is unchanged, the elastic periods grow."""
    density = DENSITY * mass_scaling
    law, friction = default_contact_laws(pack.size, E, density, GRAVITY, MU_S, MU_D)
    walls = box_walls(pack.side, pack.side, floor_z=0.0)
    return Scene.build(pack.grains, Material(E, NU, density), law, friction, planes=walls, gravity=(0, 0, -GRAVITY))


# ---------------------------------------------------------------------------- measuring steps
class _Enough(Exception):
    """Raised from the step callback: the measurement has its steps (or its time)."""


@dataclass
class Measurement:
    dts: list = field(default_factory=list)
    iterations: list = field(default_factory=list)
    contacts: list = field(default_factory=list)  # active contact pairs (feature pairs, walls included)
    grain_contacts: list = field(default_factory=list)  # distinct touching (grain, grain or wall) pairs
    wall: float = 0.0
    solve_wall: float = 0.0  # of which in the Newton systems' linear solves
    solves: int = 0
    rejected: int = 0
    last_rejection: str = ""
    partial: bool = False  # stopped by the wall-time budget before its steps
    failure: str = ""  # the integrator gave up (TimeStepTooSmall): the steps before it are kept

    @property
    def steps(self) -> int:
        return len(self.dts)


class SolveTimer:
    """Wraps the linear solve the implicit integrator calls, to split a step's time: the library
    is not touched, only the name `solve` inside `vemdem.solver.newmark` is rebound."""

    def __init__(self):
        self.seconds, self.calls = 0.0, 0

    def __enter__(self):
        self._original = newmark.solve

        def timed(K, b):
            t = time.perf_counter()
            try:
                return self._original(K, b)
            finally:
                self.seconds += time.perf_counter() - t
                self.calls += 1

        newmark.solve = timed
        return self

    def __exit__(self, *exc):
        newmark.solve = self._original


def _grain_pairs(ints: np.ndarray) -> int:
    return len(np.unique(ints[:, GRAIN_A] * (1 << 32) + ints[:, GRAIN_B])) if len(ints) else 0


def measure_steps(advance_fn, state, n_steps: int, budget: float):
    """Run `advance_fn(state, on_step, stats)` for n_steps accepted steps or until `budget` wall
    seconds have passed (checked after each step, so at least one step is taken)."""
    rec, stats, last = Measurement(), RunStats(), {"state": state}
    t0 = time.perf_counter()

    def on_step(st, info, h):
        last["state"] = st
        rec.dts.append(h)
        rec.iterations.append(info.iterations)
        rec.contacts.append(info.n_contacts)
        rec.grain_contacts.append(_grain_pairs(info.ints))
        if rec.steps >= n_steps or time.perf_counter() - t0 > budget:
            rec.partial = rec.steps < n_steps
            raise _Enough

    with SolveTimer() as solves:
        try:
            advance_fn(state, on_step, stats)
        except _Enough:
            pass
        except TimeStepTooSmall as exc:  # a finding to report, not a reason to lose the other cases
            rec.partial, rec.failure = True, str(exc)
    rec.wall = time.perf_counter() - t0
    rec.solve_wall, rec.solves = solves.seconds, solves.calls
    rec.rejected, rec.last_rejection = stats.rejected, stats.last_rejection
    return last["state"], rec


@dataclass
class Case:
    n: int
    dofs: int
    integrator: str
    rec: Measurement
    setup: float  # integrator set-up, initial state and the warm-up step (s)
    warm_up: Measurement
    stable_dt: float | None = None  # explicit: the grains' critical step times the safety factor

    def row(self) -> dict:
        r = self.rec
        wall = max(r.wall, 1e-12)
        return {
            "grains": self.n,
            "dofs": self.dofs,
            "integrator": self.integrator,
            "steps": r.steps,
            "partial": r.partial,
            "wall_s": r.wall,
            "steps_per_s": r.steps / wall,
            "grain_steps_per_s": self.n * r.steps / wall,
            "mean_contact_pairs": float(np.mean(r.contacts)) if r.steps else None,
            "mean_grain_contacts": float(np.mean(r.grain_contacts)) if r.steps else None,
            "newton_per_step": float(np.mean(r.iterations)) if r.steps else None,
            "mean_dt_s": float(np.mean(r.dts)) if r.steps else None,
            "min_dt_s": float(np.min(r.dts)) if r.steps else None,
            "simulated_s_per_wall_s": float(np.sum(r.dts)) / wall,
            "rejected": r.rejected,
            "last_rejection": r.last_rejection,
            "failure": r.failure,
            "linear_solve_s": r.solve_wall,
            "linear_solves": r.solves,
            "setup_s": self.setup,
            "warm_up": {"dt_s": self.warm_up.dts, "iterations": self.warm_up.iterations, "wall_s": self.warm_up.wall},
            "warm_up_rejected": self.warm_up.rejected,
            "stable_dt_s": self.stable_dt,
            "per_step": {"dt_s": r.dts, "iterations": r.iterations, "contact_pairs": r.contacts},
        }


def implicit_case(scene: Scene, n_steps: int, budget: float, impact_steps: float):
    """Newmark from rest. The first step is tried at dt_max and the controller finds its step in the
    untimed warm-up step, so that the measured mean dt is not a ramp up from a small first step."""
    control = StepControl(dt=DT_MAX, dt_max=DT_MAX, impact_steps=impact_steps)
    t0 = time.perf_counter()
    state = initial_state(scene)

    def go(st, on_step, stats):
        return advance(scene, st, np.inf, control, NEWMARK, on_step, stats)

    state, warm = measure_steps(go, state, 1, np.inf)
    setup = time.perf_counter() - t0
    state, rec = measure_steps(go, state, n_steps, max(budget - setup, 0.0))
    name = "implicit" + (f", impact {impact_steps:g}" if impact_steps else "")
    case = Case(scene.n_grains, 3 * scene.n_vertices, name, rec, setup, warm)
    return case, state, control


def explicit_case(scene: Scene, n_steps: int, budget: float, mass_scaling: float):
    t0 = time.perf_counter()
    integrator = ExplicitIntegrator(scene)
    control = StepControl(dt_max=DT_MAX)
    state = explicit_initial_state(scene, integrator)

    def go(st, on_step, stats):
        return advance_explicit(integrator, st, np.inf, control, on_step, stats)

    state, warm = measure_steps(go, state, 1, np.inf)
    setup = time.perf_counter() - t0
    state, rec = measure_steps(go, state, n_steps, max(budget - setup, 0.0))
    name = "explicit" + (f", mass x {mass_scaling:.0e}".replace("e+0", "e") if mass_scaling != 1 else "")
    stable = integrator.grain_dt * integrator.params.safety
    return Case(scene.n_grains, 3 * scene.n_vertices, name, rec, setup, warm, stable)


# ---------------------------------------------------------------------------- the Newton system
def newton_system(scene: Scene, state, dt: float, params: NewmarkParameters = NEWMARK):
    """K and R of the first Newton iteration of the next step, assembled as `newmark_step` does."""
    b, gam = params.beta, params.gamma
    a1, a2, a3 = 1 / (b * dt * dt), 1 / (b * dt), 1 / (2 * b) - 1
    a4, a5, a6 = gam / (b * dt), 1 - gam / b, dt * (1 - gam / (2 * b))
    t1 = state.t + dt
    travel = np.sqrt(np.max(np.sum((state.v * dt + 0.5 * state.a * dt * dt) ** 2, axis=1), initial=0.0))
    candidates = scene.contact.search(state.x, t1, margin=2.0 * travel)
    acc = -a2 * state.v - a3 * state.a
    vel = a5 * state.v + a6 * state.a
    el = scene.bodies.evaluate(state.x, tangent=True)
    cr = scene.contact.evaluate(state.x, t1, candidates, state.history, v=vel, a4=a4, tangent=True)
    M = scene.mass_matrix()
    R = M @ acc.ravel() + el.force.ravel() + cr.force.ravel() - scene.gravity_force().ravel()
    K = (a1 + params.mass_damping * a4) * M + scene.bodies.tangent_matrix(el.blocks) + cr.tangent
    return sp.csr_matrix(K), R


def _best_of(fn, repeat: int, prepare=lambda: None):
    """Best wall time of `repeat` calls (what `prepare` returns goes to fn, untimed)."""
    best, out = np.inf, None
    for _ in range(repeat):
        arg = prepare()
        t = time.perf_counter()
        out = fn(arg)
        best = min(best, time.perf_counter() - t)
    return best, out


def compare_solvers(K, R, repeat: int = 3) -> dict:
    """One solve of K y = R with SciPy (SuperLU, CSC, as vemdem.solver.linear's fallback) and with
    pypardiso. Each PARDISO solve gets a fresh solver, built outside the timer (building one loads
    MKL: about 0.25 s here), so that no factorisation is reused; its time is analysis + factorisation
    + solve, as a Newton iteration (a new matrix every time) pays it."""

    def residual(y):
        return float(np.linalg.norm(K @ y - R) / np.linalg.norm(R))

    out = {"dofs": K.shape[0], "nnz": int(K.nnz), "repeat": repeat}
    out["scipy_s"], y = _best_of(lambda _: spla.spsolve(sp.csc_matrix(K), R), repeat)
    out["scipy_residual"] = residual(y)
    try:
        import pypardiso
    except ImportError:
        return out
    t, y2 = _best_of(lambda solver: pypardiso.spsolve(K, R, solver=solver), repeat, pypardiso.PyPardisoSolver)
    out.update(pardiso_s=t, pardiso_residual=residual(y2))
    out["solution_difference"] = float(np.linalg.norm(y - y2) / np.linalg.norm(y))
    out["pardiso_over_scipy"] = t / out["scipy_s"]
    return out


def profile_step(scene: Scene, state, dt: float, top: int = 20) -> str:
    """cProfile of one implicit step (the one after the measured ones), sorted by cumulative time."""
    import cProfile
    import io
    import pstats

    profiler = cProfile.Profile()
    profiler.enable()
    _, info = newmark.newmark_step(scene, state, dt, NEWMARK)
    profiler.disable()
    text = io.StringIO()
    pstats.Stats(profiler, stream=text).sort_stats("cumulative").print_stats(top)
    return f"{info.iterations} Newton iterations, dt = {dt:.3g} s\n" + text.getvalue()


# ---------------------------------------------------------------------------- report
COLUMNS = [  # (header, key, format)
    ("N", "grains", "{:d}"),
    ("dofs", "dofs", "{:,d}"),
    ("integrator", "integrator", "{}"),
    ("steps", "steps", "{:d}"),
    ("wall s", "wall_s", "{:.1f}"),
    ("steps/s", "steps_per_s", "{:.3g}"),
    ("grain-steps/s", "grain_steps_per_s", "{:,.0f}"),
    ("contact pairs", "mean_contact_pairs", "{:,.0f}"),
    ("grain contacts", "mean_grain_contacts", "{:,.0f}"),
    ("Newton it/step", "newton_per_step", "{:.2f}"),
    ("mean dt s", "mean_dt_s", "{:.3g}"),
    ("sim s / wall s", "simulated_s_per_wall_s", "{:.3g}"),
    ("rejected", "rejected", "{:d}"),
    ("linear solve %", "solve_share", "{:.0f}"),
]


def _cells(row: dict) -> list[str]:
    row = dict(row, solve_share=100 * row["linear_solve_s"] / row["wall_s"] if row["linear_solves"] else None)
    cells = []
    for _, key, fmt in COLUMNS:
        value = row[key]
        if key == "newton_per_step" and row["integrator"].startswith("explicit"):
            value = None  # one force evaluation per step, no Newton
        text = "-" if value is None else fmt.format(value)
        cells.append(text + ("*" if key == "steps" and row["partial"] else ""))
    return cells


def print_table(rows: list[dict]):
    print("\n| " + " | ".join(h for h, _, _ in COLUMNS) + " |")
    print("|" + "|".join("---" for _ in COLUMNS) + "|")
    for row in rows:
        print("| " + " | ".join(_cells(row)) + " |")
    if any(r["partial"] for r in rows):
        print("* stopped by the wall-time budget before its steps (--budget) or by a failure: partial figures")


def print_solver(out: dict):
    line = (f"\nNewton system of {out['grains']} grains ({out['dofs']:,} dofs, {out['nnz']:,} non-zeros, dt = "
            f"{out['dt']:.3g} s), best of {out['repeat']}: SciPy spsolve {out['scipy_s']:.3f} s "
            f"(relative residual {out['scipy_residual']:.1e})")  # fmt: skip
    if "pardiso_s" in out:
        line += (f"; pypardiso {out['pardiso_s']:.3f} s (residual {out['pardiso_residual']:.1e}, solutions differ by "
                 f"{out['solution_difference']:.1e}); PARDISO / SciPy = {out['pardiso_over_scipy']:.2f}")  # fmt: skip
    else:
        line += "; pypardiso not importable"
    print(line)


def conditions() -> dict:
    import numba
    import scipy

    from vemdem.solver import linear

    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), cpu)
    except OSError:
        pass
    out = {
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "numba": numba.__version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "linear_backend": getattr(linear, "sparse_backend", lambda: "scipy")(),
        "load_average": os.getloadavg(),
    }
    try:
        import pypardiso

        out["pypardiso"] = getattr(pypardiso, "__version__", "installed")
    except ImportError:
        out["pypardiso"] = None
    return out


# ---------------------------------------------------------------------------- main
def _numbers(kind):
    return lambda text: [kind(float(v)) for v in text.split(",") if v.strip()]


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true",
                   help="64 and 515 grains, 5 implicit and 100 explicit steps, impact control off only, budget 60 s")  # fmt: skip
    p.add_argument("--grains", type=_numbers(int), help="pack sizes, comma-separated [64,515,4096]")
    p.add_argument("--integrator", choices=["implicit", "explicit", "both"], default="both")
    p.add_argument("--steps-implicit", type=int, help="accepted steps measured [20]")
    p.add_argument("--steps-explicit", type=int, help="accepted steps measured [500]")
    p.add_argument(
        "--impact-steps", type=_numbers(float), help="implicit variants: impact_steps values, 0 = off [0,20]"
    )
    p.add_argument("--mass-scaling", type=_numbers(float), default=[1.0, 1e4], help="explicit variants [1,1e4]")
    p.add_argument("--budget", type=float, help="wall seconds per case, warm-up included [120]")
    p.add_argument("--threads", type=int, help="numba threads [numba's default: one per core]")
    p.add_argument("--linear-solver", choices=["default", "scipy", "pardiso"], default="default",
                   help="back end of the implicit integrator's sparse solves (VEMDEM_LINEAR_SOLVER)")  # fmt: skip
    p.add_argument("--no-solver", action="store_true", help="skip the SciPy / PARDISO comparison")
    p.add_argument("--profile", action="store_true", help="cProfile one implicit step of the pack nearest 515 grains")
    p.add_argument("--json", type=Path, help="save the raw numbers here")
    args = p.parse_args(argv)
    quick = args.quick
    args.grains = args.grains or ([64, 515] if quick else [64, 515, 4096])
    args.steps_implicit = args.steps_implicit or (5 if quick else 20)
    args.steps_explicit = args.steps_explicit or (100 if quick else 500)
    args.impact_steps = args.impact_steps if args.impact_steps is not None else ([0.0] if quick else [0.0, 20.0])
    args.budget = args.budget or (60.0 if quick else 120.0)
    return args


def _set_linear_solver(choice: str):
    if choice == "scipy":
        os.environ["VEMDEM_LINEAR_SOLVER"] = "scipy"
    elif choice == "pardiso":
        import pypardiso  # noqa: F401  (fail here, not after minutes of set-up)

        os.environ.pop("VEMDEM_LINEAR_SOLVER", None)


def run_implicit(pack: Pack, scene: Scene, args, report: dict, solver_grains: int):
    for k, impact in enumerate(args.impact_steps):
        case, state, control = implicit_case(scene, args.steps_implicit, args.budget, impact)
        _record(case, report)
        if pack.n != solver_grains or k > 0:
            continue
        if not args.no_solver:
            K, R = newton_system(scene, state, control.dt)
            out = compare_solvers(K, R)
            report["solver"] = dict(out, grains=pack.n, dt=control.dt)
            print_solver(report["solver"])
        if args.profile:
            report["profile"] = profile_step(scene, state, control.dt)
            print("\none implicit step, cProfile by cumulative time:\n" + report["profile"], flush=True)


def run_explicit(pack: Pack, scene: Scene | None, args, report: dict):
    for factor in args.mass_scaling:
        s = scene if factor == 1.0 and scene is not None else make_scene(pack, factor)
        _record(explicit_case(s, args.steps_explicit, args.budget, factor), report)


def _record(case: Case, report: dict):
    row = dict(case.row(), load_average=os.getloadavg())
    report["cases"].append(row)
    print("  " + "  ".join(f"{h}: {c}" for (h, _, _), c in zip(COLUMNS, _cells(row))), flush=True)
    if row["rejected"]:
        print(f"    {row['rejected']} rejected steps, the last: {row['last_rejection']}", flush=True)
    if row["failure"]:
        print(f"    FAILED after {row['steps']} steps: {row['failure']}", flush=True)


def main(argv=None):
    args = parse_args(argv)
    _set_linear_solver(args.linear_solver)
    if args.threads:
        import numba

        numba.set_num_threads(args.threads)
    report = {"conditions": conditions(), "arguments": {k: str(v) for k, v in vars(args).items()}, "cases": []}
    c = report["conditions"]
    print(f"dynamics benchmark, {c['date']}, {c['cpu']}, {c['cores']} cores, numba {c['numba']} with "
          f"{c['numba_threads']} threads, linear solves: {c['linear_backend']}, load average "
          f"{c['load_average'][0]:.2f}", flush=True)  # fmt: skip
    solver_grains = min(args.grains, key=lambda n: abs(n - REFERENCE_GRAINS))
    t_all = time.perf_counter()
    for n in args.grains:
        pack = make_pack(n)
        report.setdefault("packs", []).append({"grains": n, "box_side_m": pack.side, "size_m": pack.size,
                                               "column_height_m": pack.column_height,
                                               "deposited_height_m": pack.deposited_height,
                                               "deposited_fraction": pack.deposited_fraction, "seconds": pack.seconds})  # fmt: skip
        print(f"\n{n} grains: box {pack.side * 1e3:.2f} mm, column {pack.column_height * 1e3:.0f} mm as packed, "
              f"{pack.deposited_height * 1e3:.0f} mm deposited (2 x centre of volume, packing fraction "
              f"{pack.deposited_fraction:.2f}), "
              f"{pack.seconds:.0f} s to build", flush=True)  # fmt: skip
        scene = make_scene(pack) if args.integrator != "explicit" or 1.0 in args.mass_scaling else None
        if args.integrator in ("implicit", "both"):
            run_implicit(pack, scene, args, report, solver_grains)
        if args.integrator in ("explicit", "both"):
            run_explicit(pack, scene, args, report)
    report["total_s"] = time.perf_counter() - t_all
    report["conditions"]["load_average_end"] = os.getloadavg()
    print_table(report["cases"])
    for row in report["cases"]:
        if row["integrator"].startswith("implicit") and row["mean_dt_s"] is not None:
            verdict = "reaches" if row["mean_dt_s"] >= 1e-5 else "does NOT reach"
            print(f"{row['grains']} grains, {row['integrator']}: mean dt {row['mean_dt_s']:.3g} s {verdict} 1e-5 s")
    print(
        f"\ntotal {report['total_s']:.0f} s, load average at the end {report['conditions']['load_average_end'][0]:.2f}"
    )
    if args.json:
        args.json.write_text(json.dumps(report, indent=1, default=float))
        print(f"raw numbers in {args.json}")


if __name__ == "__main__":
    main()
