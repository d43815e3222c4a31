"""Contact evaluation cost: broad + narrow phase + forces + tangent, and broad-phase scaling.

    python benchmarks/bench_contact.py [--sizes 515 4096] [--scaling 500 1000 2000 4000 8000 16000]

The pack: sand grains (1.45 mm, 20-40 vertices, random orientation) on a jittered cubic lattice
whose spacing leaves about the activation gap between neighbours' bounding spheres, so every grain
has several neighbours inside the activation gap (a dense, non-overlapping pack without running a
deposition). Friction is on (mu_s 0.6, mu_d 0.5), so the tangent includes the complex-step part.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vemdem.contact.broad import candidate_pairs
from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.model import ContactModel
from vemdem.contact.walls import box_walls
from vemdem.geometry import rotation_matrix, sand_grain


def lattice_pack(n: int, seed: int = 0, size: float = 1.45e-3, spacing_factor: float = 1.0):
    """Grains on a jittered cubic lattice of spacing `spacing_factor * size` (they may overlap)."""
    rng = np.random.default_rng(seed)
    shapes = [sand_grain(size=size, n_vertices=int(rng.integers(20, 41)), seed=seed * 100000 + i) for i in range(min(n, 64))]
    spacing = spacing_factor * size
    side = int(np.ceil(n ** (1 / 3)))
    verts, faces, ptr = [], [], [0]
    for i in range(n):
        ijk = np.array(np.unravel_index(i, (side, side, side)), float)
        centre = (ijk + 0.5) * spacing + rng.normal(scale=0.02 * spacing, size=3)
        g = shapes[i % len(shapes)]
        v = g.vertices @ rotation_matrix(rng.normal(size=3) * np.pi).T + centre
        verts.append(v)
        faces.append(g.faces)
        ptr.append(ptr[-1] + len(v))
    return np.vstack(verts), faces, np.array(ptr)


def shrink_until_apart(x, ptr, step: float = 0.99):
    """Shrink overlapping grains about their centres, 1 % at a time, until no vertex of one grain
    lies inside another: a dense pack with many gaps of the order of the activation gap."""
    from scipy.spatial import Delaunay

    x = x.copy()
    for _ in range(200):
        hulls = {}
        shrink = set()
        for a, b in candidate_pairs(x, ptr, 0.0):
            for p, q in ((a, b), (b, a)):
                if p not in hulls:
                    hulls[p] = Delaunay(x[ptr[p] : ptr[p + 1]])
                if (hulls[p].find_simplex(x[ptr[q] : ptr[q + 1]]) >= 0).any():
                    shrink.update((int(a), int(b)))
        if not shrink:
            return x
        for g in shrink:
            sl = slice(ptr[g], ptr[g + 1])
            c = x[sl].mean(axis=0)
            x[sl] = c + step * (x[sl] - c)
    raise RuntimeError("could not separate the grains")


def time_it(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def bench_evaluation(n: int, repeat: int):
    x, faces, ptr = lattice_pack(n)
    x = shrink_until_apart(x, ptr)
    law, friction = default_contact_laws(1.45e-3, 90e9, 2200.0, mu_s=0.6, mu_d=0.5)
    mass = np.full(len(ptr) - 1, 2200.0 * np.pi * 1.45e-3**3 / 6)
    lo, hi = x.min(axis=0) - 0.5 * law.activation_gap, x.max(axis=0) + 0.5 * law.activation_gap
    walls = box_walls(hi[0] - lo[0], hi[1] - lo[1], floor_z=lo[2], center=0.5 * (lo[:2] + hi[:2]))
    model = ContactModel(x, faces, ptr, mass, law, friction, planes=walls)
    v = np.zeros_like(x)
    cand = model.search(x, 0.0)
    first = model.evaluate(x, 0.0, cand, v=v, a4=1e4, tangent=True)  # compiles
    t_search, cand = time_it(lambda: model.search(x, 0.0), repeat)
    t_force, res = time_it(lambda: model.evaluate(x, 0.0, cand, first.trial_history, v=v, a4=1e4), repeat)
    t_full, res = time_it(lambda: model.evaluate(x, 0.0, cand, first.trial_history, v=v, a4=1e4, tangent=True), repeat)
    G = len(ptr) - 1
    print(f"{G:6d} grains {len(x):8d} vertices  candidate grain pairs {len(cand):7d}  active contact pairs {res.n_contacts:7d}")
    print(f"        broad phase {t_search * 1e3:8.2f} ms   narrow+forces {t_force * 1e3:8.2f} ms   "
          f"narrow+forces+tangent {t_full * 1e3:8.2f} ms   full evaluation {(t_search + t_full) * 1e3:8.2f} ms")  # fmt: skip
    print(f"        {res.n_contacts / (t_search + t_full):,.0f} contact pairs/s with tangent")
    bench_friction_tangent(model, x, cand, first.trial_history, repeat)


def bench_friction_tangent(model, x, cand, history, repeat: int):
    """The friction/damping residual with its analytic tangent (what Newton calls) against the
    residual plus the complex-step tangent it replaced, on the same pairs."""
    from vemdem.contact.friction import complex_step_tangent, dissipative_forces, dissipative_terms
    from vemdem.contact.model import pair_keys

    x_all, ints, _ = model.pairs(x, 0.0, cand)
    found, c_prev, gt_prev, stick_prev = history.lookup(pair_keys(ints))
    v_all = 1e-3 * np.random.default_rng(0).normal(size=x_all.shape)  # some pairs slip
    m = len(ints)
    common = (x_all, v_all, 1e4, ints, c_prev, gt_prev, found, stick_prev, model.law_params, model.pair_friction(ints),
              model.masses_of_pairs(ints))  # fmt: skip
    force, tangent = np.zeros((m, 6, 3)), np.zeros((m, 18, 18))
    stick, gt = np.zeros(m, dtype=np.bool_), np.zeros((m, 3))
    reference = np.zeros((m, 18, 18))

    def analytic():
        dissipative_terms(*common, force, tangent, stick, gt)

    def complex_step():
        dissipative_forces(*common, force, stick, gt)
        complex_step_tangent(*common, reference)

    analytic(), complex_step()  # compile
    t_a, _ = time_it(analytic, repeat)
    t_c, _ = time_it(complex_step, repeat)
    tangent[:] = 0.0  # dissipative_terms adds to it: the timed calls summed it repeat + 1 times
    analytic()
    err = np.abs(tangent - reference).max() / np.abs(reference).max()
    print(f"        friction+damping with tangent: analytic {t_a * 1e3:7.2f} ms, complex step {t_c * 1e3:7.2f} ms "
          f"({t_c / t_a:.1f}x), {m / t_a:,.0f} pairs/s, max difference {err:.1e} of the largest entry")  # fmt: skip


def bench_scaling(sizes, repeat: int):
    print("\nbroad-phase scaling (grain boxes in a uniform grid):")
    rows = []
    for n in sizes:
        x, _, ptr = lattice_pack(n, seed=1)
        candidate_pairs(x, ptr, 1.45e-5)
        t, pairs = time_it(lambda: candidate_pairs(x, ptr, 1.45e-5), repeat)
        rows.append((n, t))
        print(f"  {n:7d} grains  {len(pairs):8d} pairs  {t * 1e3:8.2f} ms  {n / t:,.0f} grains/s")
    if len(rows) < 2:
        return
    n, t = np.array(rows).T
    slope = np.polyfit(np.log(n), np.log(t), 1)[0]
    print(f"  scaling exponent t ~ N^{slope:.2f} (1 = linear)")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[515, 4096])
    p.add_argument("--scaling", type=int, nargs="+", default=[500, 1000, 2000, 4000, 8000, 16000])
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args(argv)
    import numba

    print(f"contact benchmark, {numba.get_num_threads()} threads")
    for n in args.sizes:
        bench_evaluation(n, args.repeat)
    bench_scaling(args.scaling, args.repeat)


if __name__ == "__main__":
    main()
