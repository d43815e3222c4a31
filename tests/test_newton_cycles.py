"""Newton's frozen pairs (solver/newmark.py, NewmarkParameters.freeze_cycles; contact.model.FrozenPairs).

The narrow phase's selection rules switch a record off where no other record takes its force over
(seen in the 515-grain lid jam: a vertex-edge pair at its edge's end, beside a vertex-face pair that
keeps the vertex-vertex pair from surviving), so the contact force jumps there and Newton can cycle
between two iterates, the pair in and out of the set, until the step is rejected. A pair found
cycling is kept in the set for the rest of the step with its latest record."""

import numpy as np
import pytest

from vemdem.contact.friction import FrictionLaw
from vemdem.contact.law import InterfaceLaw
from vemdem.contact.model import ContactModel, FrozenPairs, pair_keys
from vemdem.contact.narrow import VERTEX_VERTEX
from vemdem.contact.pairs import C0, FEATURE_A, FEATURE_B, FLOAT_COLS, INT_COLS, KIND
from vemdem.geometry import cube, rotation_matrix
from vemdem.solver.newmark import _freeze_cycling

LAW = InterfaceLaw(activation_gap=2e-5, penalty=1e9)
FRICTION = FrictionLaw(mu_s=0.5, mu_d=0.4, tangential_penalty=1e6)


def two_cubes():
    """A cube on another, turned about the vertical, face to face within the activation gap: vertex-face
    records both ways and edge-edge records where the edges cross."""
    a = cube(1e-3)
    b = cube(1e-3).rotated(rotation_matrix([0.0, 0.0, 0.3])).translated((1e-4, 5e-5, 0.0))
    lift = a.vertices[:, 2].max() - b.vertices[:, 2].min() + 1e-5
    b = b.translated((0.0, 0.0, lift))
    x = np.vstack([a.vertices, b.vertices])
    model = ContactModel(x, [a.faces, b.faces], np.array([0, 8, 16]), np.array([1.0, 1.0]), LAW, FRICTION)
    return model, x


def records(rows):
    """Synthetic records: one per (kind, feature a, feature b)."""
    ints = np.full((len(rows), INT_COLS), -1, np.int64)
    ints[:, [KIND, FEATURE_A, FEATURE_B]] = rows
    floats = np.arange(len(rows) * FLOAT_COLS, dtype=float).reshape(len(rows), FLOAT_COLS)
    return ints, floats


def test_a_frozen_record_counts_as_the_narrow_phase_would():
    model, x = two_cubes()
    cand = model.search(x, 0.0)
    full = model.evaluate(x, 0.0, cand, tangent=True)
    assert full.n_contacts >= 2
    r = int(np.argmax(np.abs(full.local_forces[0]).sum(axis=(1, 2))))
    frozen = FrozenPairs(pair_keys(full.ints[r : r + 1]), full.ints[r : r + 1].copy(), full.floats[r : r + 1].copy())
    # the narrow phase finds the record itself: kept once, the result unchanged
    again = model.evaluate(x, 0.0, cand, tangent=True, frozen=frozen)
    assert again.n_contacts == full.n_contacts
    np.testing.assert_array_equal(again.force, full.force)
    # the narrow phase misses it (as at the end of its edge): the frozen record puts its force back
    found = model.pairs

    def without_r(*args, **kw):
        x_all, ints, floats = found(*args, **kw)
        keep = pair_keys(ints) != frozen.keys[0]
        return x_all, ints[keep], floats[keep]

    model.pairs = without_r
    missed = model.evaluate(x, 0.0, cand, tangent=True)
    kept = model.evaluate(x, 0.0, cand, tangent=True, frozen=frozen)
    assert np.abs(missed.force - full.force).max() > 1e-3 * np.abs(full.force).max()  # the record matters
    np.testing.assert_allclose(kept.force, full.force, rtol=0, atol=1e-12 * np.abs(full.force).max())
    assert kept.energy == pytest.approx(full.energy, rel=1e-12)
    np.testing.assert_allclose(np.sort(kept.pair_tangent.ravel()), np.sort(full.pair_tangent.ravel()), rtol=1e-12)
    assert model.potential(x, 0.0, cand, frozen) == pytest.approx(full.energy, rel=1e-12)


def test_a_kept_record_another_record_took_over_is_not_counted_twice():
    """At a hand-over (a vertex-face pair that became the vertex-edge pair at the face's edge) the
    leaving record and the one taking over have the same two closest points: only one counts. The
    flexible head-on impact rebounded 0.24 % faster before this rule (tests/test_rigid.py)."""
    model, x = two_cubes()
    cand = model.search(x, 0.0)
    full = model.evaluate(x, 0.0, cand, tangent=True)
    r = int(np.argmax(np.abs(full.local_forces[0]).sum(axis=(1, 2))))
    ints, floats = full.ints[r : r + 1].copy(), full.floats[r : r + 1].copy()
    ints[0, FEATURE_B] += 1000  # another record's identity, at the same two points: a hand-over
    handed = FrozenPairs(pair_keys(ints), ints, floats)
    again = model.evaluate(x, 0.0, cand, tangent=True, frozen=handed)
    assert again.n_contacts == full.n_contacts
    np.testing.assert_array_equal(again.force, full.force)
    # a record whose closest point lies half a gbar and more from every found one is a lost force:
    # kept (its point moved 0.05 of a 1 mm face or edge, 2.5 gbar)
    assert ints[0, KIND] != VERTEX_VERTEX
    floats[0, C0] += 0.05
    lost = FrozenPairs(pair_keys(ints), ints, floats)
    far = model.evaluate(x, 0.0, cand, tangent=True, frozen=lost)
    assert far.n_contacts == full.n_contacts + 1


def test_a_found_frozen_twin_of_a_steady_record_is_held_out():
    """The settling 110-grain pack of paper-compression-implicit (t = 0.1127 s) stalled Newton on an
    edge-edge record at its edge's end (s = 0.999999), the twin of the end vertex's vertex-face
    record (gaps 1.06854e-5 and 1.06851e-5 m): found at every other iterate, it doubled that spot's
    force, and steps of 1e-4 and 1e-5 s cycled until rejected. Frozen, such a found twin is held
    out for the rest of the step: the spot counts once, as where the narrow phase drops it."""
    model, x = two_cubes()
    cand = model.search(x, 0.0)
    full = model.evaluate(x, 0.0, cand, tangent=True)
    r = int(np.argmax(np.abs(full.local_forces[0]).sum(axis=(1, 2))))
    twin_ints, twin_floats = full.ints[r : r + 1].copy(), full.floats[r : r + 1].copy()
    twin_ints[0, FEATURE_B] += 1000  # another record's identity at the same two closest points
    found = model.pairs

    def with_twin(*args, **kw):
        x_all, ints, floats = found(*args, **kw)
        return x_all, np.vstack([ints, twin_ints]), np.vstack([floats, twin_floats])

    model.pairs = with_twin
    doubled = model.evaluate(x, 0.0, cand, tangent=True)
    assert doubled.n_contacts == full.n_contacts + 1
    assert np.abs(doubled.force - full.force).max() > 1e-3 * np.abs(full.force).max()  # counted twice
    frozen = FrozenPairs(pair_keys(twin_ints), twin_ints, twin_floats)
    held = model.evaluate(x, 0.0, cand, tangent=True, frozen=frozen)
    assert held.n_contacts == full.n_contacts
    np.testing.assert_array_equal(held.force, full.force)
    assert held.energy == pytest.approx(full.energy, rel=1e-12)
    assert model.potential(x, 0.0, cand, frozen) == pytest.approx(full.energy, rel=1e-12)


def test_a_pair_in_out_in_is_frozen_with_its_latest_record():
    steady, toggling, entering = (0, 1, 2), (2, 3, 4), (1, 5, 6)
    trail, frozen = [], None
    sequence = [[steady, toggling], [steady], [steady, toggling, entering]]
    for rows in sequence:
        ints, floats = records(rows)
        frozen = _freeze_cycling(trail, ints, floats, frozen)
    assert frozen is not None
    np.testing.assert_array_equal(frozen.keys, pair_keys(records([toggling])[0]))
    np.testing.assert_array_equal(frozen.ints, ints[1:2])  # the record of the latest iteration
    np.testing.assert_array_equal(frozen.floats, floats[1:2])


def test_a_pair_out_in_out_is_frozen_with_the_record_it_had():
    steady, toggling = (0, 1, 2), (2, 3, 4)
    trail, frozen = [], None
    for rows in ([steady], [steady, toggling], [steady]):
        ints, floats = records(rows)
        if len(rows) == 2:
            seen_ints, seen_floats = ints[1:2].copy(), floats[1:2].copy()
        frozen = _freeze_cycling(trail, ints, floats, frozen)
    np.testing.assert_array_equal(frozen.ints, seen_ints)
    np.testing.assert_array_equal(frozen.floats, seen_floats)


def test_a_frozen_pair_left_out_for_its_twin_stays_frozen():
    """A frozen pair that neither of the last two iterates' records hold (a twin carried its spot, so
    contact.model._with_frozen left it out) stays frozen with its stored record for the rest of the
    step, as FrozenPairs promises: should the twin leave, the stored record carries the spot. It
    used to be dropped from the frozen set two iterations later."""
    steady, toggling = (0, 1, 2), (2, 3, 4)
    trail, frozen = [], None
    for rows in ([steady, toggling], [steady], [steady, toggling]):
        ints, floats = records(rows)
        frozen = _freeze_cycling(trail, ints, floats, frozen)
    stored = frozen.ints.copy(), frozen.floats.copy()
    for _ in range(4):  # left out for its twin from here on
        frozen = _freeze_cycling(trail, *records([steady]), frozen)
        np.testing.assert_array_equal(frozen.keys, pair_keys(records([toggling])[0]))
        np.testing.assert_array_equal(frozen.ints, stored[0])
        np.testing.assert_array_equal(frozen.floats, stored[1])


def test_pairs_that_join_or_leave_once_are_not_frozen():
    a, b, c = (0, 1, 2), (2, 3, 4), (1, 5, 6)
    trail, frozen = [], None
    for rows in ([a, b], [a, b, c], [a, c], [a, c]):  # c joins, b leaves: no cycle
        frozen = _freeze_cycling(trail, *records(rows), frozen)
    assert frozen is None


def test_the_config_key_reaches_newton():
    import tomllib

    from vemdem.config.build import solver_options_from
    from vemdem.scenarios.registry import checked_config, example_text
    from vemdem.solver.newmark import NewmarkParameters

    assert NewmarkParameters().freeze_cycles is True  # on by default: docs/dynamics.md says why
    cfg = tomllib.loads(example_text("drop"))
    assert solver_options_from(checked_config(dict(cfg))[0]).freeze_cycles is True
    cfg["solver"].update(freeze_cycles=False, max_iterations=40, easy_iterations=20)
    cfg, _ = checked_config(cfg)
    options = solver_options_from(cfg)
    assert (options.freeze_cycles, options.max_iterations, options.easy_iterations) == (False, 40, 20)


def test_the_solver_defaults_are_one_set():
    """`[solver]`'s defaults live in the config table (what users see in `vemdem example` and the
    docs) and in SolverOptions (what the library's callers get): they must not drift apart."""
    import dataclasses

    from vemdem.config.tables import SOLVER
    from vemdem.solver.api import SolverOptions

    defaults = {f.name: f.default for f in dataclasses.fields(SolverOptions)}
    assert set(defaults) <= set(SOLVER)
    for key, value in defaults.items():
        assert SOLVER[key].default == value, key


def test_pairs_that_flip_between_stick_and_slip_three_times_are_broken():
    """cycles.StickFlips: a pair whose stick flag changed at three iterations (not necessarily
    consecutive) is listed as broken; the change from the first iterate (the predictor) to the second
    is not counted; one change, a pair that joins late, or a pair that leaves is not listed."""
    from vemdem.contact.model import ContactHistory
    from vemdem.solver.cycles import StickFlips

    def h(keys, stick):
        return ContactHistory(np.array(keys, np.int64), np.zeros((len(keys), 2)), np.zeros((len(keys), 3)),
                              np.array(stick, bool))  # fmt: skip

    flips = StickFlips()
    assert flips.times == 3 and flips.skip_first
    flips.update(h([1, 2, 3, 4], [1, 1, 1, 1]))
    flips.update(h([1, 2, 3, 4], [0, 1, 1, 1]))  # 1 changes at the first update: the predictor's miss
    flips.update(h([1, 2, 3, 4], [1, 0, 1, 1]))  # 1 and 2 change, counted once each
    flips.update(h([1, 2, 3, 5], [1, 1, 0, 0]))  # 2 changes back (twice), 3 once, 4 leaves, 5 joins
    assert flips.broken.tolist() == []
    flips.update(h([1, 2, 3, 5], [1, 0, 0, 1]))  # 2's third change; 5 once
    assert flips.broken.tolist() == [2]
    flips.update(h([1, 2, 3, 5], [0, 1, 0, 1]))  # 1's second counted change, 2's fourth
    flips.update(h([1, 2, 3, 5], [1, 1, 0, 1]))  # 1's third, two iterations after its first
    assert flips.broken.tolist() == [1, 2]


def test_pairs_whose_damping_switches_three_times_go_on_undamped():
    """cycles.DampingFlips: a pair is damped at an iterate where its dissipative force is not zero
    (the no-adhesion clamp zeroes damping and friction together); a pair whose damping switched on or
    off at three iterates, the first update's change not counted, is listed, read from the records'
    features whatever their order in the contact result."""
    from types import SimpleNamespace

    from vemdem.contact.model import pair_keys
    from vemdem.contact.pairs import FEATURE_A, FEATURE_B, INT_COLS, KIND
    from vemdem.solver.cycles import DampingFlips

    ints = np.zeros((3, INT_COLS), np.int64)
    ints[:, KIND], ints[:, FEATURE_A], ints[:, FEATURE_B] = 1, [7, 3, 5], [11, 12, 13]
    keys = pair_keys(ints)

    def result(damped, order=(0, 1, 2)):
        local = np.zeros((3, 6, 3))
        local[np.array(damped, bool), 0, 2] = 1e-7
        order = list(order)
        return SimpleNamespace(ints=ints[order], local_forces=(np.zeros((3, 6, 3)), local[order]))

    flips = DampingFlips()
    assert flips.times == 3 and flips.skip_first
    flips.update(result([1, 1, 1]))
    flips.update(result([0, 1, 1]))  # the predictor's miss: not counted
    flips.update(result([1, 0, 1], order=(2, 0, 1)))
    flips.update(result([0, 1, 1], order=(1, 2, 0)))
    assert flips.broken.tolist() == []
    flips.update(result([1, 0, 1]))  # the first and the second record: their third counted change
    assert flips.broken.tolist() == sorted(keys[:2].tolist())
    without = SimpleNamespace(ints=ints, local_forces=(np.zeros((3, 6, 3)),))  # no friction law: nothing to hold
    fresh = DampingFlips()
    for _ in range(5):
        fresh.update(without)
    assert fresh.broken.tolist() == []
