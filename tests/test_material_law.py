"""The material's contact law (contact/defaults.material_contact_laws): its penalty branch against
Hertz's force-overlap law and stiffness written from the two-sphere formulas, its potential
against differences, its tangential penalty against Mindlin's, bad input, and the lab tests'
law, the same at every stress (docs/contact.md, one law per material)."""

import numpy as np
import pytest

from vemdem.contact.defaults import material_contact_laws
from vemdem.contact.law import normal_force, normal_potential

D, E, NU = 0.9e-3, 90e9, 0.16


def hertz(E1, nu1, R1, E2, nu2, R2):
    """Hertz's sphere-sphere contact: (F(delta), k(delta)) from 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2,
    1/R = 1/R1 + 1/R2, contact radius a = sqrt(R delta), F = 4 E* a^3 / (3 R), k = 2 E* a."""
    e_star = 1.0 / ((1 - nu1**2) / E1 + (1 - nu2**2) / E2)
    radius = 1.0 / (1.0 / R1 + 1.0 / R2)

    def law(delta):
        a = np.sqrt(radius * delta)
        return 4.0 * e_star * a**3 / (3.0 * radius), 2.0 * e_star * a

    return law


@pytest.mark.parametrize("E_, nu, d", [(E, NU, D), (10e6, 0.4, 1.2e-3), (70e9, -0.3, 2e-4)])
def test_the_penalty_branch_is_hertz_between_two_spheres_of_the_grain(E_, nu, d):
    law, _ = material_contact_laws(d, E_, nu)
    p = law.packed()
    reference = hertz(E_, nu, d / 2, E_, nu, d / 2)
    gbar = law.activation_gap
    assert gbar == pytest.approx(0.01 * d)
    for delta in np.geomspace(1e-6, 0.999, 25) * (gbar - law.switch_gap):
        g = gbar - delta
        f, k = normal_force(g, p)
        f_ref, k_ref = reference(gbar - g)  # the overlap the gap stands for, to the last bit
        assert f == pytest.approx(f_ref, rel=1e-12)
        assert k == pytest.approx(k_ref, rel=1e-12)


def test_the_stiffness_grows_as_the_force_to_the_one_third():
    law, _ = material_contact_laws(D, E, NU)
    p = law.packed()
    deltas = np.geomspace(1e-4, 0.9, 12) * (law.activation_gap - law.switch_gap)
    f, k = np.array([normal_force(law.activation_gap - x, p) for x in deltas]).T
    slope = np.polyfit(np.log(f), np.log(k), 1)[0]
    assert slope == pytest.approx(1.0 / 3.0, abs=1e-9)


def test_the_potential_is_the_integral_of_the_force():
    law, _ = material_contact_laws(D, E, NU)
    p = law.packed()
    for g in np.append(np.linspace(0.05, 0.995, 40), 1.1) * law.activation_gap:
        h = 1e-6 * g
        fd = -(normal_potential(g + h, p) - normal_potential(g - h, p)) / (2 * h)
        assert fd == pytest.approx(normal_force(g, p)[0], rel=1e-6, abs=1e-9 * law.switch_force)


@pytest.mark.parametrize("nu", [-0.5, 0.0, 0.16, 0.3, 0.49])
def test_the_tangential_penalty_is_mindlins_at_the_switch_force(nu):
    """Mindlin: k_t = 8 G* a with 1/G* = (2 - nu1)/G1 + (2 - nu2)/G2, G = E / (2 (1 + nu)), against
    Hertz's k_n = 2 E* a at the same contact radius, the switch gap's."""
    law, friction = material_contact_laws(D, E, nu)
    G = E / (2 * (1 + nu))
    g_star = 1.0 / (2 * (2 - nu) / G)
    e_star = 1.0 / (2 * (1 - nu**2) / E)
    k_n = normal_force(law.switch_gap, law.packed())[1]
    assert friction.tangential_penalty == pytest.approx(8 * g_star / (2 * e_star) * k_n, rel=1e-12)


def test_a_layer_modulus_replaces_the_grains_modulus_in_the_law():
    law, _ = material_contact_laws(D, E, NU)
    soft, _ = material_contact_laws(D, E, NU, layer_modulus=E / 10)
    reference = hertz(E / 10, NU, D / 2, E / 10, NU, D / 2)
    delta = 0.5 * (soft.activation_gap - soft.switch_gap)
    assert normal_force(soft.activation_gap - delta, soft.packed())[0] == pytest.approx(reference(delta)[0], rel=1e-12)
    assert soft.penalty == pytest.approx(law.penalty / 10, rel=1e-12)


@pytest.mark.parametrize("args, key", [
    ((D, E, 0.5), "material.nu"), ((D, E, -1.0), "material.nu"), ((D, E, float("nan")), "material.nu"),
    ((D, 0.0, NU), "material.E"), ((D, float("inf"), NU), "material.E"), ((0.0, E, NU), "grain size"),
])  # fmt: skip
def test_bad_material_input_names_its_key(args, key):
    with pytest.raises(ValueError, match=key):
        material_contact_laws(*args)


@pytest.mark.parametrize("overrides, key", [
    ({"layer_modulus": -1.0}, "contact.layer_modulus"), ({"reference_force": 1.0}, "contact.reference_force"),
    ({"penalty_exponent": 2.0}, "contact.penalty_exponent"), ({"stickiness": 1.0}, "stickiness"),
])  # fmt: skip
def test_bad_contact_input_names_its_key(overrides, key):
    with pytest.raises(ValueError, match=key):
        material_contact_laws(D, E, NU, **overrides)


# ---------------------------------------------------------------------------- the lab tests' law
def _oedometer(stress: float, **contact) -> dict:
    from vemdem.scenarios.registry import checked_config

    raw = {"scenario": "oedometer", "pack": {"n_grains": 60, "grains": {"size": D}},
           "material": {"E": E, "nu": NU, "density": 2200.0}, "contact": {"mu_s": 0.15, **contact},
           "stages": [{"stress": stress / 2}, {"stress": stress}]}  # fmt: skip
    return checked_config(raw)[0]


def _law_of(cfg: dict, size: float = D):
    from vemdem.config.build import contact_laws_from, material_from

    law, friction = contact_laws_from(cfg, size, material_from(cfg))
    return np.append(law.packed(), friction.packed())


@pytest.mark.parametrize("scenario", ["oedometer", "triaxial", "isotropic", "direct_shear"])
def test_a_lab_tests_law_does_not_depend_on_its_stress(scenario):
    """Two configs at 25 kPa and 1 MPa give the same law, the material's; its pack settles under
    it too."""
    from vemdem.scenarios.pack import pack_config
    from vemdem.scenarios.registry import checked_config

    def config(stress):
        if scenario == "oedometer":
            return _oedometer(stress)
        stresses = {"triaxial": {"consolidation": {"stress": stress}}, "direct_shear": {"normal": {"stress": stress}},
                    "isotropic": {"stages": [{"stress": stress}]}}[scenario]  # fmt: skip
        raw = {"scenario": scenario, "pack": {"n_grains": 60, "grains": {"size": D}},
               "material": {"E": E, "nu": NU, "density": 2200.0}, **stresses}  # fmt: skip
        return checked_config(raw)[0]

    low, high = config(25e3), config(1e6)
    assert low["contact"]["law"] == "material"
    assert np.array_equal(_law_of(low), _law_of(high))
    law, _ = material_contact_laws(D, E, NU)
    assert np.array_equal(_law_of(low)[:7], law.packed())
    pack = pack_config(low)
    assert pack["contact"]["law"] == "material"
    assert np.array_equal(_law_of(pack)[:7], law.packed())


def test_a_given_reference_force_is_the_per_stress_law_for_the_test_and_its_pack():
    from vemdem.scenarios.oedometer import pack_config_for

    force = 2 * 1e6 * D**2  # the law the oedometer once set for 1 MPa
    cfg = _oedometer(1e6, reference_force=force)
    law = _law_of(cfg)
    assert law[3] == 2.0  # n1: the per-force law
    p = law[:7]
    assert normal_force(p[1], p)[0] == pytest.approx(force, rel=1e-12)
    assert np.array_equal(_law_of(pack_config_for(cfg))[:7], p)


def test_the_material_law_in_a_config_names_its_bad_keys():
    from vemdem.config import ConfigError

    with pytest.raises(ConfigError, match="contact.layer_modulus"):
        _oedometer(1e5, layer_modulus=-5.0)
    with pytest.raises(ConfigError, match="contact.penalty_exponent"):
        _law_of(_oedometer(1e5, penalty_exponent=2.0))
    with pytest.raises(ConfigError, match="contact.layer_modulus"):  # only the material's law has one
        _law_of(_oedometer(1e5, layer_modulus=1e9, law="weight"))
    soft = _law_of(_oedometer(1e5, layer_modulus=E / 100))
    assert soft[2] == pytest.approx(_law_of(_oedometer(1e5))[2] / 100, rel=1e-12)
