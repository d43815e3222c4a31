"""Pairs whose contact law has no root for Newton within a step (docs/dynamics.md): a stick flag or
a normal damping that flips between iterates. Both implicit integrators (solver/newmark.py for
flexible grains, solver/rigid_implicit.py for rigid ones) count the flips per step and, from the
third, hold such a pair on one branch (contact.model's `slipping` and `undamped`)."""

from __future__ import annotations

import numpy as np

from ..contact.model import pair_keys


class Flips:
    """The pairs whose flag (stick; damped) changed between Newton iterates (sorted pair keys):
    `broken` lists those that changed at `times` iterations of the step. The change from the first
    iterate to the second is not counted when `skip_first`: it is the predictor's miss, not a cycle."""

    skip_first = True
    times = 3

    def __init__(self):
        self.keys = self.flags = None
        self.flipped = [np.zeros(0, np.int64)]
        self.broken = np.zeros(0, np.int64)
        self.seen = 0

    def update_flags(self, keys: np.ndarray, flags: np.ndarray) -> None:
        """keys sorted and unique, flags the pairs' booleans at this iterate."""
        self.seen += 1
        if self.keys is not None and not (self.skip_first and self.seen == 2):
            _, a, b = np.intersect1d(self.keys, keys, assume_unique=True, return_indices=True)
            flipped = self.keys[a[self.flags[a] != flags[b]]]
            if len(flipped):
                self.flipped.append(flipped)
                every, counts = np.unique(np.concatenate(self.flipped), return_counts=True)
                self.broken = every[counts >= self.times]
        self.keys, self.flags = keys, flags


class StickFlips(Flips):
    """Pairs whose stick flag changed at three iterates (NewmarkParameters.break_stick_cycles)."""

    def update(self, history) -> None:
        self.update_flags(history.keys, history.stick)


class DampingFlips(Flips):
    """Pairs whose normal damping switched on or off at three iterates (hold_damping_cycles): the
    no-adhesion clamp F_N = max(f_n + F_d, 0) zeroes a pair's damping and friction where the pair
    separates faster than f_n / c_n, and at the outer edge of the layer, where f_n is 1e-12 N and
    the damping 2 zeta sqrt(k m) |g_n dot| 1e-7 N, Newton's iterates crossed that kink both ways
    every other iteration (docs/dynamics.md). A pair is damped where its dissipative force is not 0."""

    def update(self, cr) -> None:
        if len(cr.local_forces) < 2 or not len(cr.ints):
            return self.update_flags(np.zeros(0, np.int64), np.zeros(0, bool))
        keys, first = np.unique(pair_keys(cr.ints), return_index=True)
        damped = np.any(cr.local_forces[1][first] != 0.0, axis=(1, 2))
        self.update_flags(keys, damped)


class HeldPairs:
    """One step's two rules together (break_stick_cycles, hold_damping_cycles; either may be off):
    what contact.evaluate is to hold, updated from each iterate's contact result."""

    def __init__(self, break_stick: bool, hold_damping: bool):
        self.stick = StickFlips() if break_stick else None
        self.damping = DampingFlips() if hold_damping else None

    def held(self) -> dict:
        """contact.evaluate's `slipping` and `undamped` (None: that rule is off)."""
        return {"slipping": None if self.stick is None else self.stick.broken,
                "undamped": None if self.damping is None else self.damping.broken}  # fmt: skip

    def update(self, cr) -> None:
        if self.stick is not None:
            self.stick.update(cr.trial_history)
        if self.damping is not None:
            self.damping.update(cr)

    def counts(self) -> tuple[int, int]:
        """(pairs held to mu_d, pairs held undamped): StepInfo's broken_pairs and undamped_pairs."""
        return tuple(0 if rule is None else len(rule.broken) for rule in (self.stick, self.damping))
