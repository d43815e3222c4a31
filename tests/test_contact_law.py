"""Normal interface law (docs/contact.md): fixture values, continuity, potential, stiffness."""

import numpy as np
import pytest
from scipy.integrate import quad

from vemdem.contact.law import InterfaceLaw, normal_force, normal_potential, normal_stiffness_slope

# The GIRAFFE manual's syntax example: EPN1 1e8, N1 2, N2 -2, GNB 2e-4, Factor 0.3
MANUAL = InterfaceLaw(activation_gap=2e-4, penalty=1e8, penalty_exponent=2, switch_factor=0.3, barrier_exponent=-2)


def test_fixture_values():
    p = MANUAL.packed()
    assert MANUAL.switch_gap == pytest.approx(6e-5)
    assert p[4] == pytest.approx(3.024e-9, rel=1e-12)  # eps2
    assert p[6] == pytest.approx(1.12, rel=1e-12)  # c2
    for g, f in [(1.5e-4, 0.25), (1e-4, 1.0), (6e-5, 1.96), (3e-5, 4.48), (1e-5, 31.36), (1e-6, 3025.12)]:
        assert normal_force(g, p)[0] == pytest.approx(f, rel=1e-12)
    assert normal_force(6e-5, p)[1] == pytest.approx(2.8e4, rel=1e-12)
    assert normal_potential(6e-5, p) == pytest.approx(9.14666666e-5, rel=1e-8)


@pytest.mark.parametrize("law", [MANUAL, InterfaceLaw(2e-5, 3e9, 2.5, 0.2, -3.0), InterfaceLaw(1.0, 1.0, 1.0, 0.5, -1.5)])
def test_continuity_at_switch_gap(law):
    p = law.packed()
    gbb = law.switch_gap
    h = 1e-9 * gbb
    f_lo, k_lo = normal_force(gbb - h, p)
    f_hi, k_hi = normal_force(gbb + h, p)
    assert f_lo == pytest.approx(f_hi, rel=1e-7)  # C0
    assert k_lo == pytest.approx(k_hi, rel=1e-6)  # C1
    assert normal_force(law.activation_gap, p) == (0.0, 0.0)
    assert normal_force(2 * law.activation_gap, p) == (0.0, 0.0)
    assert normal_force(0.0, p)[0] == np.inf and normal_potential(0.0, p) == np.inf


@pytest.mark.parametrize("law", [MANUAL, InterfaceLaw(2e-5, 3e9, 2.5, 0.2, -3.0)])
def test_potential_is_the_integral_of_the_force(law):
    p = law.packed()
    gbar, gbb = law.activation_gap, law.switch_gap
    for g in np.linspace(0.05 * gbar, 1.2 * gbar, 23):
        pts = [gbb] if g < gbb else None
        integral = quad(lambda s: normal_force(s, p)[0], g, max(g, gbar), points=pts, epsabs=0, epsrel=1e-12, limit=200)[0]
        assert normal_potential(g, p) == pytest.approx(integral, rel=1e-9, abs=1e-300)


@pytest.mark.parametrize("law", [MANUAL, InterfaceLaw(2e-5, 3e9, 2.5, 0.2, -3.0)])
def test_stiffness_is_minus_the_derivative_of_the_force(law):
    p = law.packed()
    for g in np.linspace(0.05, 0.98, 31) * law.activation_gap:
        h = 1e-7 * g
        fd = -(normal_force(g + h, p)[0] - normal_force(g - h, p)[0]) / (2 * h)
        assert normal_force(g, p)[1] == pytest.approx(fd, rel=1e-6)
        dphi = (normal_potential(g + h, p) - normal_potential(g - h, p)) / (2 * h)
        assert -dphi == pytest.approx(normal_force(g, p)[0], rel=1e-6)


@pytest.mark.parametrize("law", [MANUAL, InterfaceLaw(2e-5, 3e9, 2.5, 0.2, -3.0), InterfaceLaw(2e-5, 3e9, 1.0)])
def test_stiffness_slope_is_the_derivative_of_the_stiffness(law):
    p = law.packed()
    for g in np.append(np.linspace(0.05, 0.98, 31), 1.2) * law.activation_gap:
        h = 1e-7 * g
        fd = (normal_force(g + h, p)[1] - normal_force(g - h, p)[1]) / (2 * h)
        assert normal_stiffness_slope(g, p) == pytest.approx(fd, rel=1e-6, abs=1e-3 * abs(normal_force(g, p)[1]) / g)


@pytest.mark.parametrize(
    "kwargs", [{"activation_gap": 0.0}, {"penalty": -1.0}, {"switch_factor": 1.0}, {"barrier_exponent": -1.0}]
)
def test_bad_parameters(kwargs):
    base = dict(activation_gap=1e-4, penalty=1e8)
    base.update(kwargs)
    with pytest.raises(ValueError, match="contact law"):
        InterfaceLaw(**base)


def test_default_parameters_follow_the_grain():
    from vemdem.contact.defaults import default_contact_laws

    d, E, rho = 1.45e-3, 90e9, 2200.0
    law, fr = default_contact_laws(d, E, rho, mu_s=0.6, mu_d=0.5)
    p = law.packed()
    weight = rho * np.pi * d**3 / 6 * 9.81
    assert law.activation_gap == pytest.approx(0.01 * d)
    f_switch, k_switch = normal_force(law.switch_gap, p)
    assert f_switch == pytest.approx(10 * weight, rel=1e-12)  # F_ref reached where the barrier starts
    assert fr.tangential_penalty == pytest.approx(k_switch, rel=1e-12)
    assert (fr.mu_s, fr.mu_d, fr.damping_ratio) == (0.6, 0.5, 0.5)
    # a very soft, heavy material: the cap keeps the contact no stiffer than the grain
    law_soft, _ = default_contact_laws(d, 1e3, rho)
    assert normal_force(law_soft.switch_gap, law_soft.packed())[1] == pytest.approx(1e3 * d, rel=1e-12)
    # a given reference force is capped likewise
    law_given, _ = default_contact_laws(d, 1e3, rho, reference_force=1.0)
    assert normal_force(law_given.switch_gap, law_given.packed())[1] == pytest.approx(1e3 * d, rel=1e-12)
    law2, fr2 = default_contact_laws(d, E, rho, activation_gap=2e-5, damping_ratio=0.1)
    assert law2.activation_gap == 2e-5 and fr2.damping_ratio == 0.1
    with pytest.raises(ValueError, match="unknown parameter 'stickiness'"):
        default_contact_laws(d, E, rho, stickiness=1.0)
    with pytest.raises(ValueError, match="must not exceed mu_s"):
        default_contact_laws(d, E, rho, mu_s=0.2, mu_d=0.3)


def test_reference_force_is_the_force_at_the_switch_gap():
    """`reference_force` (a lid run: its force over its contacts) replaces 10 grain weights as the
    force where the barrier takes over; the stiffness and the tangential penalty follow it."""
    from vemdem.contact.defaults import default_contact_laws

    d, E, rho = 1.45e-3, 90e9, 2200.0
    law, fr = default_contact_laws(d, E, rho, mu_s=0.15, reference_force=100.0)
    f_switch, k_switch = normal_force(law.switch_gap, law.packed())
    assert f_switch == pytest.approx(100.0, rel=1e-12)
    assert k_switch == pytest.approx(2 * 100.0 / (law.activation_gap - law.switch_gap), rel=1e-12)  # n1 = 2
    assert fr.tangential_penalty == pytest.approx(k_switch, rel=1e-12)
    assert law.switch_force == pytest.approx(100.0, rel=1e-12)  # what summary.json reports
