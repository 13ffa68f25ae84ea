"""``skinkit bench fem`` with several sizes and several peers: one row per size, each peer's
entry beside skinkit's figures (a peer that raises is reported as failed and the others still
run), and NGSolve's answer on the same mesh equal to skinkit's."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.bench import fem
from skinkit.cli import cli

pytestmark = pytest.mark.needs_plugins

HAVE_NGSOLVE = importlib.util.find_spec("ngsolve") is not None


calls: list[int] = []


def _fake_peer(mesh) -> dict:
    """A peer that answers skinkit's own vertex displacements, a little off, with round figures:
    0.7 s per iteration on its first run of a mesh, 0.5 s on the second."""
    calls.append(mesh.n_elements)
    u = fem.run_skinkit(round(mesh.n_elements ** (1 / 3)))["u"][: int(mesh.t.max()) + 1]
    s_it = 0.7 if calls.count(mesh.n_elements) % 2 else 0.5
    return {"u": u * (1 + 1e-9), "wall": 4 * s_it, "s_per_newton": s_it, "factorisations": 4,
            "tangent_assembly_s": 0.25, "solve_s": 0.2}


def _inverts(mesh) -> dict:
    raise ValueError(" warp violation!\n")


def test_several_sizes_give_a_row_each_and_a_failing_peer_does_not_stop_the_others():
    calls.clear()
    res = fem.run_sizes([1, 2], peers=("sfepy", "ngsolve"),
                        runners={"sfepy": _inverts, "ngsolve": _fake_peer}, repeat=2)
    assert calls == [1, 1, 8, 8] and res["repeat"] == 2   # each size twice, the fastest kept
    assert [row["n"] for row in res["sizes"]] == [1, 2]
    assert [row["dof"] for row in res["sizes"]] == [81, 375]
    # the first size's figures stay at the top, under the keys a one-size run always had
    assert res["dof"] == 81 and res["skinkit_s_per_newton"] == res["sizes"][0]["skinkit_s_per_newton"]
    for row in res["sizes"]:
        assert row["skinkit_s_per_newton"] > 0 and row["skinkit_factorisations"] >= 1
        sf, ng = row["peers"]["sfepy"], row["peers"]["ngsolve"]
        assert sf["status"] == "failed" and sf["error"] == "sfepy failed: ValueError: warp violation!"
        assert row["peer_error"] == sf["error"] and row["sfepy_s_per_newton"] is None
        assert sf["s_per_newton"] is None and sf["ratio_s_per_newton"] is None
        assert ng["status"] == "ok" and ng["error"] is None and ng["factorisations"] == 4
        assert ng["s_per_newton"] == 0.5 and ng["wall_s"] == 2.0
        assert ng["ratio_s_per_newton"] == pytest.approx(0.5 / row["skinkit_s_per_newton"])
        assert ng["ratio_tangent_assembly"] == pytest.approx(0.25 / row["tangent_assembly_s"])
        assert ng["max_rel_disp_diff"] == pytest.approx(1e-9, rel=1e-3)
        # per converged step: the peer's one load step against skinkit's
        assert ng["s_per_step"] == 2.0 and row["skinkit_steps"] == 1
        assert ng["ratio_s_per_step"] == pytest.approx(2.0 / row["skinkit_s_per_step"])
        assert row["skinkit_factorisations_per_step"] == row["skinkit_factorisations"]
    lines = fem.summary_lines(res)
    assert [ln.split(":")[0] for ln in lines if ln.startswith("n = ")] == ["n = 1", "n = 2"]
    assert sum(ln == "sfepy   no figures: sfepy failed: ValueError: warp violation!" for ln in lines) == 2
    assert sum(ln.startswith("ngsolve 2.000 s/step") and "0.500 s/iteration" in ln for ln in lines) == 2
    rows = fem.table_rows(res)
    assert [(r[0], r[2]) for r in rows] == [("1", "skinkit"), ("1", "sfepy"), ("1", "ngsolve"),
                                            ("2", "skinkit"), ("2", "sfepy"), ("2", "ngsolve")]
    assert all(len(r) == len(fem.COLUMNS) for r in rows)


def test_sizes_on_the_command_line_repeated_or_comma_separated(monkeypatch, tmp_path):
    seen = []
    real = fem.run_sizes

    def run_sizes(sizes, linear, peers, repeat):
        seen.append((list(sizes), tuple(peers), repeat))
        return real(sizes, linear, peers, runners={"sfepy": _inverts}, repeat=repeat)

    monkeypatch.setattr(fem, "run_sizes", run_sizes)
    page = tmp_path / "fem.md"
    r = CliRunner().invoke(cli, ["bench", "fem", "--n", "1", "--n", "2,1", "--peer", "sfepy", "--repeat", "2",
                                 "--json", "--page", str(page)])
    assert r.exit_code == 0, r.output
    assert seen == [([1, 2, 1], ("sfepy",), 2)]
    res = json.loads(r.stdout)
    assert [row["n"] for row in res["sizes"]] == [1, 2, 1] and "threads" in res and res["repeat"] == 2
    text = page.read_text()
    assert "skinkit bench fem --n 1 --n 2,1 --peer sfepy --repeat 2" in text and text.count("| sfepy |") == 3
    for bad in (["--n", "0"], ["--n", "7,x"], ["--n", ","]):
        r = CliRunner().invoke(cli, ["bench", "fem", *bad])
        assert r.exit_code == 2 and "--n" in r.output


@pytest.mark.skipif(not HAVE_NGSOLVE, reason="NGSolve is not installed (pip install 'skinkit[bench]')")
def test_ngsolve_on_the_same_mesh_gives_skinkits_answer():
    from skinkit.bench.fem_ngsolve import ngsolve_mesh, run_ngsolve

    n = 3
    sk = fem.run_skinkit(n)
    nv = int(sk["mesh"].t.max()) + 1
    M = ngsolve_mesh(sk["mesh"])
    assert (M.nv, M.ne) == (nv, n ** 3)
    assert set(M.GetBoundaries()) == {"bottom", "top", "free"}
    import ngsolve as ng

    assert ng.Integrate(ng.CF(1.0), M) == pytest.approx(1.0, rel=1e-12)   # the unit block
    # the interpreted integrand: the same answer without a C++ compiler, faster to set up
    out = run_ngsolve(sk["mesh"], fem.MU, fem.BULK, fem.TOP_U, compiled=False)
    assert out["ndof"] == sk["dof"]
    scale = np.abs(sk["u"]).max()
    assert np.abs(out["u"] - sk["u"][:nv]).max() <= 1e-9 * scale
    np.testing.assert_allclose(out["u"][sk["mesh"].node_sets["top"][sk["mesh"].node_sets["top"] < nv]],
                               np.tile(fem.TOP_U, (sum(sk["mesh"].node_sets["top"] < nv), 1)), atol=1e-15)
    assert out["residuals"][-1] <= 1e-10 and out["factorisations"] == len(out["residuals"])
    # through the bench: the entry of the peer, its ratios to skinkit
    row = fem.compare(sk, peers=("ngsolve",), runners={
        "ngsolve": lambda mesh: run_ngsolve(mesh, fem.MU, fem.BULK, fem.TOP_U, compiled=False)})
    ng_entry = row["peers"]["ngsolve"]
    assert ng_entry["status"] == "ok" and ng_entry["max_rel_disp_diff"] <= 1e-9
    assert ng_entry["inverse"] == "sparsecholesky" and ng_entry["ratio_s_per_newton"] > 0
