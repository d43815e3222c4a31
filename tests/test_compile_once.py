"""Every kernel compiles once per run (a fresh install's first run is mostly compilation).

Numba compiles a jitted callee once per distinct argument type, and two habits doubled that
silently: an integer literal argument is typed by its value (Literal[int](3)), so each call site
with another constant compiled the callee again (`_record` eight times), and a prange index is
uint64 inside the parallel body but int64 when the loop is typed outside it (`_pair_force` twice).
The check runs the main job's path (rigid grains, explicit) and the paper's (flexible grains,
implicit) in a fresh interpreter, so no other test's calls add signatures, and then lists every
vemdem kernel that holds more than one.
"""

import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import sys
    import textwrap
    from numba.core.registry import CPUDispatcher
    from vemdem.cli import main

    out = sys.argv[1]
    common = '''
    [material]
    E = 90e9
    nu = 0.16
    density = 2200.0
    [contact]
    mu_s = 0.9
    mu_d = 0.8
    [collapse]
    open = "corner"
    [settle]
    kinetic_threshold = 1e-3
    max_time = {t}
    [output]
    every = {t}
    vtk = false
    '''
    rigid = '''
    scenario = "pile_collapse"
    [pack]
    n_grains = 6
    seed = 1
    [pack.grains]
    size = 1.45e-3
    vertices = 12
    [pack.box]
    width = 3.5e-3
    depth = 3.5e-3
    [model]
    grains = "rigid"
    [solver]
    integrator = "explicit"
    mass_scaling = 1.0
    ''' + common.format(t=2e-3)
    flexible = f'''
    scenario = "pile_collapse"
    initial_state = "{out}/rigid/pack/state.npz"
    [model]
    grains = "flexible"
    [solver]
    integrator = "implicit"
    mass_scaling = 1.0
    ''' + common.format(t=5e-4)
    for name, text in (("rigid", rigid), ("flexible", flexible)):
        path = f"{out}/{name}.toml"
        open(path, "w").write(textwrap.dedent(text))
        try:
            main(["run", path, "--out", f"{out}/{name}"])
        except SystemExit as exc:
            assert not exc.code, f"the {name} run failed"
    for mod_name, mod in list(sys.modules.items()):
        if mod_name.startswith("vemdem"):
            for attr, obj in vars(mod).items():
                if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == mod_name and len(obj.signatures) > 1:
                    print(f"twice {mod_name}.{attr}: " + " | ".join(str(s) for s in obj.signatures))
    print("checked")
    """
)


def test_every_kernel_compiles_once(tmp_path):
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path)], capture_output=True, text=True,
                          timeout=1800)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert lines and lines[-1] == "checked", proc.stdout[-3000:]
    # narrow._dot and friction._dot3 take contiguous vectors and matrix columns (two layouts): a
    # second compilation of a two-line function, kept for the readability of its call sites
    tolerated = ("twice vemdem.contact.narrow._dot:", "twice vemdem.contact.friction._dot3:")
    twice = [line for line in lines if line.startswith("twice ") and not line.startswith(tolerated)]
    assert not twice, "kernels compiled more than once:\n" + "\n".join(twice)
