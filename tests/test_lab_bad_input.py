"""Bad input to the laboratory tests (oedometer, triaxial, direct shear, isotropic) as a new user
writes it: each is refused in one line naming the key (exit status 2), before a pack settles
where the config alone tells; a pack read from `initial_state` is checked once it is read, before
any step (docs/servo.md, what a lab test refuses). A sample that comes apart in a run stops it
with the stage and the key of its target; a shear test that never loaded its sample reports no
friction angle instead of a negative one."""

import copy
import tomllib
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_bad_input import assert_one_line_error, setter, to_toml

from vemdem.scenarios.registry import example_text

EXAMPLES = {name: tomllib.loads(example_text(name)) for name in ("oedometer", "triaxial", "direct-shear", "isotropic",
                                                                  "drop")}  # fmt: skip
OEDOMETER, TRIAXIAL, SHEAR, ISOTROPIC, DROP = EXAMPLES.values()
PACK30 = Path(__file__).parent / "data" / "pack30_mu015.npz"  # 30 grains of 1.45 mm in a 5 mm x 5 mm box

CASES = [
    # the run was bounded by nothing: a 4-second oedometer ran on to the first frame at 1,000 s
    ("oedometer: every past the stages", OEDOMETER, setter("output.every", 1e3),
     "output.every: must not exceed the stages' max_time added up (4 s), got 1000"),
    ("isotropic: every past the stages", ISOTROPIC, setter("output.every", 5.0),
     "output.every: must not exceed the stages' max_time added up (3 s)"),
    ("triaxial: every past the stages", TRIAXIAL, setter("output.every", 1e3),
     "output.every: must not exceed consolidation.max_time + shear.max_time (10.1 s)"),
    ("direct shear: every past the stages", SHEAR, setter("output.every", 1e3),
     "output.every: must not exceed normal.max_time + shear.max_time (10.1 s)"),
    # the frame count counts the stages, not the pack's re-equilibration (settle.max_time, 1 s)
    ("oedometer: a million frames", OEDOMETER, setter("output.every", 1e-6), "output.every: 1e-06 s writes 4e+06 frames"),
    ("oedometer: a stage of 1e300 s", OEDOMETER, setter("stages.1.max_time", 1e300),
     "stages[1].max_time: must be in (0, 1e4] s"),
    ("triaxial: consolidation of 1e300 s", TRIAXIAL, setter("consolidation.max_time", 1e300),
     "consolidation.max_time: must be in (0, 1e4] s"),
    ("triaxial: shear of 1e300 s", TRIAXIAL, setter("shear.max_time", 1e300), "shear.max_time: must be in (0, 1e4] s"),
    ("direct shear: consolidation of 1e300 s", SHEAR, setter("normal.max_time", 1e300),
     "normal.max_time: must be in (0, 1e4] s"),
    ("isotropic: a stage of 1e300 s", ISOTROPIC, setter("stages.0.max_time", 1e300),
     "stages[0].max_time: must be in (0, 1e4] s"),
    # once TimeStepTooSmall, naming no key; a vanishing area reported 5e296 Pa
    ("oedometer: lid area in mm^2", OEDOMETER, setter("lid.area", 16.0),
     "lid.area: 16 m^2 is 1e6 times the box's section (1.6e-5 m^2, pack.box.width x pack.box.depth)"),
    ("oedometer: lid area in cm^2", OEDOMETER, setter("lid.area", 0.16), "lid.area: 0.16 m^2 is 1e4 times"),
    ("oedometer: lid area a thousandth", OEDOMETER, setter("lid.area", 1.6e-8), "lid.area: 1.6e-8 m^2 is 0.001 times"),
    ("oedometer: vanishing lid area", OEDOMETER, setter("lid.area", 1e-300), "lid.area: must be in [1e-12, 100] m^2"),
    # one grain once reported K0 = 0, a one-grain triaxial a friction angle of 16 degrees
    ("oedometer: one grain", OEDOMETER, setter("pack.n_grains", 1),
     "pack.n_grains: an oedometer sample of 1 grain measures its walls, not a granular material; at least 4 grains"),
    ("triaxial: one grain", TRIAXIAL, setter("pack.n_grains", 1), "pack.n_grains: a triaxial sample of 1 grain"),
    ("direct shear: three grains", SHEAR, setter("pack.n_grains", 3), "pack.n_grains: a direct shear sample of 3 grains"),
    ("isotropic: two grains", ISOTROPIC, setter("pack.n_grains", 2), "pack.n_grains: an isotropic sample of 2 grains"),
    # the pack was ignored without a word
    ("oedometer: initial_state beside [pack]", OEDOMETER, setter("initial_state", "pack/state.npz"),
     "initial_state: given beside a [pack] table, which the run would ignore"),
    ("triaxial: initial_state beside [pack]", TRIAXIAL, setter("initial_state", "pack/state.npz"), "[pack] table"),
    # the servo's area, speed and gain were ignored without a word
    ("scene: servo without a stress", DROP, setter("walls.0.servo", {"stress": [], "area": 1e-4, "max_speed": 1e-3}),
     ("walls[0].servo.stress: empty or not given, so the wall has no servo and its servo.area, servo.max_speed "
      "would be ignored")),
    ("scene: servo's gain alone", DROP, setter("walls.0.servo", {"gain": 0.5}),
     "walls[0].servo.stress: empty or not given, so the wall has no servo and its servo.gain would be ignored"),
]


@pytest.fixture
def no_runs(monkeypatch):
    """A config these tests expect refused must not start its run (a pack of 240 grains)."""
    from vemdem.scenarios.registry import SCENARIOS, scenario_module

    def ran(*args, **kwargs):
        raise AssertionError("the config was not refused: its run started")

    for name in SCENARIOS:
        monkeypatch.setattr(scenario_module(name), "run", ran)


@pytest.mark.parametrize("base,mutate,needle", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_lab_config_is_one_line_naming_the_key(tmp_path, cli, no_runs, base, mutate, needle):
    cfg = copy.deepcopy(base)
    mutate(cfg)
    path = tmp_path / "job.toml"
    path.write_text(to_toml(cfg))
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, needle)
    assert not (tmp_path / "out").exists()


def test_the_examples_and_a_reduced_test_sample_pass_the_lab_rules():
    """The bounds leave the shipped examples alone, and the tests' few-grain samples too (a warning
    where they run, no refusal): the examples hold 60-240 grains, the tests 4-20."""
    from vemdem.config.lab_rules import FEW_GRAINS, MIN_GRAINS
    from vemdem.scenarios.registry import EXAMPLES as ALL
    from vemdem.scenarios.registry import checked_config

    for name in ALL:
        checked_config(tomllib.loads(example_text(name)))
    small = copy.deepcopy(OEDOMETER)
    small["pack"]["n_grains"] = MIN_GRAINS
    checked_config(small)
    assert MIN_GRAINS <= 4 < FEW_GRAINS <= 60


# ------------------------------------------------------------------ a pack read from a file
def _state(tmp_path, n_grains: int | None = None) -> str:
    """tests/data's 30-grain pack, or its first n_grains grains, as a state file in tmp_path."""
    from vemdem.io.state import load_state, save_state

    pack = load_state(PACK30)
    n = len(pack.grains) if n_grains is None else n_grains
    end = sum(g.n_vertices for g in pack.grains[:n])
    save_state(tmp_path / "state.npz", pack.grains[:n], pack.x[:end], pack.v[:end], pack.meta)
    return "state.npz"


def _from_state(tmp_path, base: dict, **changes) -> Path:
    """`base` from the state file, its stages cut short and its grains rigid: a config that the
    check under test lets through runs for seconds, not minutes, before the test fails."""
    cfg = copy.deepcopy(base)
    del cfg["pack"]
    cfg["initial_state"] = _state(tmp_path, changes.pop("n_grains", None))
    cfg.update(model={"grains": "rigid"}, solver={"integrator": "explicit"})
    for stage in cfg.get("stages", []):
        stage["max_time"] = 2e-3
    for key, value in changes.items():
        setter(key.replace("__", "."), value)(cfg)
    path = tmp_path / "job.toml"
    path.write_text(to_toml(cfg))
    return path


def test_a_state_of_two_grains_is_refused_naming_initial_state(tmp_path, cli):
    code, _, err = cli("run", _from_state(tmp_path, OEDOMETER, n_grains=2), "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, "initial_state: an oedometer sample of 2 grains measures its walls")
    assert not (tmp_path / "out").exists()


def test_a_lid_area_off_the_states_box_is_refused(tmp_path, cli):
    # the state's box is 5 mm x 5 mm: 25 mm^2, and 1e-3 m^2 is 40 times that
    path = _from_state(tmp_path, OEDOMETER, lid__area=1e-3)
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, "lid.area: 0.001 m^2 is 40 times the box's section (2.5e-5 m^2, the box of ")
    assert "state.npz" in err
    assert not (tmp_path / "out").exists()


def test_every_past_the_triaxial_shear_is_refused_before_a_step(tmp_path, cli):
    """0.5 s is within the max_time (1.001 s), but the shear ends at its 25 % strain: 0.25 / rate,
    rate = I sqrt(sigma / rho) / d = 5e-4 sqrt(50e3 / 2200) / 1.45 mm, 0.15 s."""
    path = _from_state(tmp_path, TRIAXIAL, output__every=0.5, consolidation__max_time=1e-3, shear__max_time=1.0)
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, "output.every: must not exceed the test's length (0.153 s: consolidation.max_time, "
                                     "then the shear to shear.max_strain at shear.inertia_number), got 0.5")  # fmt: skip
    assert not (tmp_path / "out" / "triaxial.csv").exists()


def test_a_sample_of_a_few_grains_runs_with_one_warning_line():
    from vemdem.config import ConfigError
    from vemdem.scenarios.lab import SmallSampleWarning, check_sample

    cfg = {"scenario": "triaxial", "initial_state": "state.npz"}
    with pytest.warns(SmallSampleWarning, match=r"^initial_state: a triaxial sample of 12 grains: .* 30 grains or more"):
        check_sample(cfg, SimpleNamespace(grains=[None] * 12))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_sample(cfg, SimpleNamespace(grains=[None] * 30))
    with pytest.raises(ConfigError, match=r"^initial_state: a triaxial sample of 3 grains .* at least 4 grains"):
        check_sample(cfg, SimpleNamespace(grains=[None] * 3))


# ------------------------------------------------------------------ a sample that comes apart
class HeldServo:
    """A servo wall of unit area that measures a set force and stands still."""

    def __init__(self, force=1.0):
        self.force, self.target, self.max_speed, self.keep_secant = force, 0.0, 1.0, False
        self.motion = SimpleNamespace(speed=0.0)

    @property
    def stress(self):
        return self.force

    def measure(self, reactions, ints, floats, t):
        pass

    def travel_at(self, t):
        return 0.0

    def steer(self, t):
        pass


def _path(servo, key="stages[1].stress"):
    from vemdem.lab.path import LoadPath, Stage

    stages = [Stage(1e3, 1.0, key="stages[0].stress"), Stage(1e9, 1.0, key=key)]
    region = (np.full(3, -1.0), np.full(3, 1.0))
    path = LoadPath([servo], stages, lambda t, start: 0.0, np.ones(8), np.array([0, 4, 8]), region=region)
    path.current = 1
    return path


def _after_step(path, x):
    state = SimpleNamespace(t=0.0125, x=x)
    info = SimpleNamespace(wall_reactions=None, ints=None, floats=None, iterations=0)
    path.after_step(state, info)


@pytest.mark.parametrize("where,value,problem", [
    ((5, 2), np.nan, "the sample's state became non-finite at t = 0.0125 s"),
    ((5, 2), np.inf, "the sample's state became non-finite"),
    ((6, 0), 2.5, "grain 1 left the cell at t = 0.0125 s: the grains flew apart"),
    ((1, 1), -3.0, "grain 0 left the cell"),
])  # fmt: skip
def test_a_sample_that_comes_apart_stops_the_test_naming_its_stage_and_key(where, value, problem):
    from vemdem.lab.path import SampleFailed

    x = np.zeros((8, 3))
    x[where] = value
    with pytest.raises(SampleFailed) as err:
        _after_step(_path(HeldServo()), x)
    assert str(err.value).startswith(f"stage 1 (stages[1].stress = 1e+09 Pa): {problem}")
    assert "\n" not in str(err.value)


def test_a_non_finite_wall_force_stops_the_test_and_a_whole_sample_does_not():
    from vemdem.lab.path import SampleFailed

    with pytest.raises(SampleFailed, match=r"^stage 1 \(stages\[1\]\.stress = 1e\+09 Pa\): the sample's state became"):
        _after_step(_path(HeldServo(force=np.inf)), np.zeros((8, 3)))
    path = _path(HeldServo())
    _after_step(path, np.full((8, 3), 0.5))  # inside the cell, finite: the stage goes on
    assert path.current == 1 and path.records[-1].steps == 1


@pytest.mark.parametrize(("step", "warned"), [(4e-9, True), (2e-7, False)])
def test_a_stage_its_steps_project_to_days_is_named_in_a_warning(step, warned):
    """A 1e9 Pa target on rigid grains steps at about 4e-9 s: 2.5e8 steps to a max_time of 1 s."""
    from vemdem.lab.path import PROJECTED_AFTER, StageTooLong

    path = _path(HeldServo())
    info = SimpleNamespace(wall_reactions=None, ints=None, floats=None, iterations=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for k in range(PROJECTED_AFTER + 5):
            path.after_step(SimpleNamespace(t=k * step, x=np.zeros((8, 3))), info)
    lines = [str(w.message) for w in caught if issubclass(w.category, StageTooLong)]
    assert len(lines) == (1 if warned else 0)
    if warned:
        assert lines[0].startswith("stage 1 (stages[1].stress = 1e+09 Pa): 2.5e+08 steps to its end (1 s)"), lines


@pytest.mark.parametrize("base,table,stage", [(OEDOMETER, "oedometer.csv", "stage 0 (stages[0].stress = 25000 Pa)"),
                                              (TRIAXIAL, "triaxial.csv", "consolidation (consolidation.stress = 50000 Pa)")])
def test_a_run_whose_grains_leave_the_cell_stops_in_one_line_without_a_summary(tmp_path, cli, monkeypatch, base, table,
                                                                               stage):  # fmt: skip
    """The scenarios hand the path their cell's region and their stages' keys: a region that the
    pack's top grains are already out of (the cell's upper half cut away) stops the run at its
    first step, exit status 1 as a run that fails after its start, naming the stage and its key."""
    from vemdem.lab import cell

    whole = cell.cell_region

    def cut(centre, box, floor, height):
        lower, upper = whole(centre, box, floor, height)
        return lower, np.array([upper[0], upper[1], floor + 0.5 * height])

    monkeypatch.setattr(cell, "cell_region", cut)
    code, _, err = cli("run", _from_state(tmp_path, base), "--out", tmp_path / "out", "--quiet")
    lines = err.strip().splitlines()
    assert code == 1 and lines[0].startswith(f"vemdem: run failed: SampleFailed: {stage}: grain "), err
    assert "left the cell at t = " in lines[0] and "Traceback" not in err
    assert not (tmp_path / "out" / "summary.json").exists()
    assert not (tmp_path / "out" / table).exists()  # the failing step's frame, its first, is never written


# ------------------------------------------------------------------ a shear test that never loaded its sample
def _triaxial_rows(sigma_1, sigma_3, volumetric):
    from vemdem.analysis.triaxial import HEADER

    n = len(sigma_1)
    rows = np.zeros((n, len(HEADER)))
    rows[:, HEADER.index("stage")] = 1
    rows[:, HEADER.index("axial_strain")] = np.linspace(0.0, 0.03, n)
    rows[:, HEADER.index("volumetric_strain")] = volumetric
    rows[:, HEADER.index("sigma_1")], rows[:, HEADER.index("sigma_3")] = sigma_1, sigma_3
    return rows


def test_a_triaxial_whose_platen_never_loaded_the_sample_reports_no_friction_angle():
    """A short run from an unconsolidated sample: sigma_1 below sigma_3 throughout (once
    phi_peak_deg = -2.75 and -16.7), the lateral walls still closing in (once a NaN dilatancy
    angle and a bare arcsin warning)."""
    from vemdem.analysis.triaxial import triaxial_figures

    axial = np.linspace(0.0, 0.03, 7)
    out = triaxial_figures(_triaxial_rows(np.linspace(5.0, 1.1e4, 7), np.linspace(1.9e3, 2e4, 7), 2.0 * axial))
    assert "phi_peak_deg" not in out and "sigma_1_peak_Pa" not in out
    assert out["peak_error"].startswith("sigma_1 never exceeded sigma_3 in the shear (largest ratio 0.55)")
    assert "dilatancy_angle_deg" not in out and "shrank faster than the axial strain" in out["dilatancy_error"]
    # a loaded sample keeps its angle: R = 3 is 30 degrees
    loaded = triaxial_figures(_triaxial_rows(np.full(7, 3e4), np.full(7, 1e4), -0.1 * axial))
    assert loaded["phi_peak_deg"] == pytest.approx(30.0) and "peak_error" not in loaded


def test_a_shear_without_a_friction_angle_says_so_in_one_warning_line():
    from vemdem.analysis.direct_shear import peak, peak_stresses
    from vemdem.scenarios.lab import UnmeasuredWarning, warn_unmeasured

    with pytest.raises(ValueError, match="never rose above 0"):
        peak(np.linspace(0.0, 1e-3, 5), np.array([-0.2, -0.1, -0.05, np.nan, -0.3]))
    with pytest.raises(ValueError, match="no peak state"):
        peak_stresses(np.array([-0.2, -0.1]), np.array([1e3, 1e3]), np.array([-200.0, -100.0]))
    with pytest.warns(UnmeasuredWarning, match=r"^phi_peak_deg not reported \(summary.json peak_error\): why$"):
        warn_unmeasured({"peak_error": "why", "E50_error": "other"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_unmeasured({"phi_peak_deg": 35.0, "E50_error": "not the headline"})


def test_a_test_driven_past_the_quasi_static_inertia_number_says_so_in_one_line():
    from vemdem.scenarios.lab import QUASI_STATIC, RateWarning, warn_if_not_quasi_static

    from vemdem.scenarios.registry import checked_config

    cfg, _ = checked_config(tomllib.loads(example_text("triaxial")))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_if_not_quasi_static(cfg)  # the example's I = 5e-4: quiet
    fast = tomllib.loads(example_text("triaxial"))
    fast["solver"]["mass_scaling"] = 100.0
    fast["shear"]["inertia_number"] = 5.0 * QUASI_STATIC
    cfg, _ = checked_config(fast)
    with pytest.warns(RateWarning, match=r"shear.inertia_number = 0.005 at mass_scaling 100: the density integrated"):
        warn_if_not_quasi_static(cfg)
