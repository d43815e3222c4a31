"""What mass scaling does to a collision: a head-on impact of two sand grains (verification/impact.py).

    python benchmarks/bench_mass_scaling.py [--scalings 1e6 1e5 1e4 1e3 1] [--speed 0.05]
    python benchmarks/bench_mass_scaling.py --selective [--scalings 1e7 1e6 1e5 1e4 1e3 100 0]
                                            [--reference-force F] [--durations 4]

Prints, per mass scaling and integrator: the grain's vibration period over the contact duration
(Scene.vibration_contact_ratio), the restitution of the centres' velocities, the kinetic energy
kept (vibration included), steps and wall time. Results: docs/validation.md (mass scaling).
`--selective`: the scalings are selective mass scaling's lambda at the real density (0: off);
`--reference-force` a stiffer contact law (N per contact at the switch gap, as a laboratory test's
stress sets it), `--durations` how many contact durations the run lasts after first contact (a
stiff law's shallow contacts last longer than its nominal duration). Results:
docs/selective-mass-scaling.md.
"""

from __future__ import annotations

import argparse
import time

from vemdem.verification.impact import head_on


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scalings", type=float, nargs="+", default=[1e6, 1e5, 1e4, 1e3, 1.0])
    ap.add_argument("--speed", type=float, default=0.05, help="approach speed (m/s)")
    ap.add_argument("--skip-explicit-real", action="store_true", help="skip the explicit run at scaling 1 (~100k steps)")
    ap.add_argument("--selective", action="store_true", help="scalings are selective mass scaling's lambda")
    ap.add_argument("--reference-force", type=float, default=None, help="the contact law's reference force (N)")
    ap.add_argument("--durations", type=float, default=4.0, help="contact durations simulated after first contact")
    args = ap.parse_args()
    if args.selective:
        selective(args)
        return
    print(f"{'scaling':>8} {'integrator':>10} {'T_g/t_c':>8} {'restitution':>11} {'energy kept':>11} {'steps':>7} {'wall s':>7}")
    runs = [(s, "explicit") for s in args.scalings if not (s == 1.0 and args.skip_explicit_real)]
    runs += [(1.0, "implicit")]
    reference = None
    for scaling, integrator in runs:
        t0 = time.perf_counter()
        r = head_on(scaling, integrator, speed=args.speed)
        if integrator == "explicit" and scaling <= 1e3:
            reference = r.restitution
        print(f"{scaling:8.0e} {integrator:>10} {r.vibration_contact_ratio:8.3f} {r.restitution:11.3f} "
              f"{r.energy_kept:11.3f} {r.steps:7d} {time.perf_counter() - t0:7.1f}", flush=True)
    if reference:
        print(f"restitution of the explicit runs at scaling <= 1e3 (the converged value): {reference:.3f}")


def selective(args) -> None:
    """The impact at the real density under selective mass scaling lambda, and implicitly."""
    print(f"{'lambda':>8} {'integrator':>10} {'T_g/t_c':>8} {'restitution':>11} {'energy kept':>11} {'steps':>7} {'wall s':>7}")
    runs = [(0.0, "implicit")] + [(lam, "explicit") for lam in args.scalings]
    for lam, integrator in runs:
        t0 = time.perf_counter()
        r = head_on(1.0, integrator, speed=args.speed, selective_mass_scaling=lam,
                    reference_force=args.reference_force, contact_durations=args.durations)  # fmt: skip
        print(f"{lam:8.0e} {integrator:>10} {r.vibration_contact_ratio:8.3f} {r.restitution:11.4f} "
              f"{r.energy_kept:11.4f} {r.steps:7d} {time.perf_counter() - t0:7.1f}", flush=True)


if __name__ == "__main__":
    main()
