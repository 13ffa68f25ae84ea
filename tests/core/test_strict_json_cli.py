"""Every ``--json`` output is strict JSON: no NaN, no Infinity (``skinkit.jsonio.loads_strict``).

The click tree is walked for every command with a ``--json`` option. Each is either run here on
a small input (through the CLI, in this process) or listed in ``EXPENSIVE`` with the reason, so
a new ``--json`` command cannot escape the check silently.
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from skinkit import jsonio
from skinkit.cli import cli
from skinkit.examples import example_model

pytestmark = pytest.mark.needs_plugins

REAL = Path("/work/shared/data/real/healthy_skin_extension_relaxation.csv")
if not REAL.is_file():   # beside the checkout, where the other tests find it
    REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real" / REAL.name
#: seconds of the real record the model commands read (its first relaxation cycle starts there)
SHORT_ROWS = 3000

#: --json commands not run here, and why
EXPENSIVE: dict[str, str] = {
    "bench coverage": "fits 20 virtual sessions per case (minutes to hours)",
    "bench diagnose": "diagnoses two finite-element sessions, truths on their own meshes (minutes)",
    "bench fem": "needs its peers (sfepy, NGSolve), solves a 10,000-unknown block once per code",
    "bench fit": "three fits of a finite-element model (minutes)",
    "bench fit-invivo": "fits at in vivo scale (hours)",
    "bench mesh-nulls": "diagnoses 40 finite-element sessions, truths on their own meshes (tens of minutes)",
    "bench mesh-error": "solves a truth on a mesh of its own and the model on its mesh refined 2x (minutes; "
                        "its figures: tests/inverse/test_mesh_error_check.py)",
    "bench scar": "diagnoses virtual two-pad scar sessions, about twenty minutes each (its scoring "
                  "and journal: tests/gap/test_scar_benchmark.py)",
    "bench forward": "starts a Dask cluster and solves finite-element sessions (minutes)",
    "bench robot": "streams six link configurations in real time through emulators",
    "convergence": "solves a finite-element model on several meshes (minutes)",
    "demo": "the whole chain on a virtual session (minutes)",
    "gap benchmark": "diagnoses many virtual sessions (minutes to hours)",
    "gap thesis-case": "a finite-element diagnosis (minutes)",
    "solve": "a finite-element solve of a model file (tens of seconds to minutes)",
}


def _json_commands() -> list[str]:
    def walk(group: click.Group, ctx: click.Context, prefix: tuple[str, ...] = ()):
        for name in group.list_commands(ctx):
            cmd = group.get_command(ctx, name)
            if isinstance(cmd, click.Group):
                yield from walk(cmd, click.Context(cmd, parent=ctx), (*prefix, name))
            elif cmd is not None and not cmd.hidden:
                if any(isinstance(p, click.Option) and "--json" in p.opts for p in cmd.params):
                    yield " ".join((*prefix, name))

    return sorted(walk(cli, click.Context(cli)))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Small inputs: the lumped model, the start of the real record, an experiment, a linear
    record for sysid, two speckle images with points."""
    import cv2

    from skinkit.sysid.lti import SecondOrder
    from skinkit.sysid.simulate import simulate_record
    from skinkit.vision import planar
    from skinkit.vision.sensor import Sensor
    from skinkit.vision.texture import SpeckleTexture

    if not REAL.is_file():
        pytest.skip("shared real data not beside the checkout")
    d = tmp_path_factory.mktemp("strict-json")
    short = d / "record.csv"
    with open(REAL, encoding="utf-8") as f:
        short.write_text("".join(f.readline() for _ in range(SHORT_ROWS + 1)))
    exp = d / "session.h5"
    r = CliRunner().invoke(cli, ["import-csv", str(exp), str(short), "--axis", "x"])
    assert r.exit_code == 0, r.output
    rec = simulate_record(SecondOrder(K=1450.0, B=4.76, I=0.04), duration_s=2.0, rate_hz=1000.0, seed=0)
    t = np.arange(rec.force_N.size) / 1000.0
    lines = ["time_s,tip_force_z_N,tip_position_z_m"]
    lines += [f"{a:.9g},{b:.9g},{c:.9g}" for a, b, c in zip(t, rec.force_N, rec.position_m, strict=True)]
    sysid_csv = d / "linear.csv"
    sysid_csv.write_text("\n".join(lines) + "\n")
    rng = np.random.default_rng(4)
    tex, sen = SpeckleTexture(cell=5.0, seed=21), Sensor(noise=0.01)
    cv2.imwrite(str(d / "ref.png"), sen.expose(planar.render(tex, (120, 160)), rng))
    cv2.imwrite(str(d / "cur.png"), sen.expose(planar.render(tex, (120, 160), planar.translation(2.4, 0.7)),
                                              rng))
    (d / "pts.csv").write_text("x_px,y_px\n80,60\n70.5,55.2\n")
    return {"dir": d, "model": example_model("extension_relaxation_lumped"), "record": short,
            "experiment": exp, "sysid": sysid_csv}


def _cases(p: dict[str, Path]) -> dict[str, list[str]]:
    """The arguments each cheap --json command runs with."""
    m, rec, d = str(p["model"]), str(p["record"]), p["dir"]
    return {
        "plugins": ["plugins", "--json"],
        "inspect": ["inspect", str(p["experiment"]), "--json"],
        "robot protocols": ["robot", "protocols", "--json"],
        "robot run": ["robot", "run", "normal_indentation", "--param", "frequency=4", "--param", "periods=1",
                      "--param", "peak_to_peak=0.0005", "--out", str(d / "run.h5"), "--json"],
        "effects list": ["effects", "list", "--json"],
        "effects visibility": ["effects", "visibility", m, "--session", rec, "--json"],
        "predict": ["predict", m, rec, "--json"],
        "fit": ["fit", m, rec, "--json", "--out", str(d / "fit")],
        "grid": ["grid", m, rec, "--pair", "lumped.a,lumped.b", "--n", "3", "--json",
                 "--out", str(d / "grid")],
        "profile-likelihood": ["profile-likelihood", m, rec, "--parameter", "lumped.a", "--n", "3", "--json",
                               "--out", str(d / "profile")],
        "select": ["select", m, rec, "--subsets", "lumped.a,lumped.b;lumped.a", "--folds", "none",
                   "--json"],
        "design": ["design", m, rec, "--json"],
        "gap diagnose": ["gap", "diagnose", m, rec, "--max-effects", "0", "--json"],
        "sysid": ["sysid", str(p["sysid"]), "--json"],
        "verify": ["verify", "--case", "patch-test", "--json"],
        "vision track": ["vision", "track", str(d / "ref.png"), str(d / "cur.png"), "--points",
                         str(d / "pts.csv"), "--subset", "48", "--json"],
        "bench store": ["bench", "store", "--blocks", "3", "--block", "50", "--json"],
        "bench sysid": ["bench", "sysid", "--repeat", "1", "--json"],
        "bench cli": ["bench", "cli", "--repeat", "1", "--robot-seconds", "0.5", "--json"],
    }


#: commands of _cases that need the hardware distribution (the sim driver)
NEEDS_HARDWARE = {"robot run"}


#: the names of the cheap commands (their arguments need the inputs fixture)
CHEAP = sorted(_cases(dict.fromkeys(("model", "record", "experiment", "sysid", "dir"), Path("."))))


def test_every_json_command_is_run_or_listed_as_expensive():
    found = set(_json_commands())
    cheap = set(CHEAP)
    assert not cheap & set(EXPENSIVE), cheap & set(EXPENSIVE)
    missing = found - cheap - set(EXPENSIVE)
    assert not missing, f"--json commands neither run here nor listed in EXPENSIVE: {sorted(missing)}"
    stale = (cheap | set(EXPENSIVE)) - found
    assert not stale, f"no such --json command any more: {sorted(stale)}"


@pytest.mark.parametrize("command", CHEAP)
def test_json_output_is_strict(inputs, command):
    if command in NEEDS_HARDWARE:
        from skinkit import registry

        if "sim" not in registry.names("skinkit.drivers"):
            pytest.skip("needs the sim driver (skinkit-hardware)")
    args = _cases(inputs)[command]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, (command, r.output[-2000:])
    data = jsonio.loads_strict(r.stdout)
    assert isinstance(data, (dict, list)) and data, command
