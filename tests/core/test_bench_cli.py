"""``skinkit bench cli``: the figures are there and consistent (no wall-clock assertion)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from skinkit.cli import cli


def test_bench_cli_json():
    r = CliRunner().invoke(cli, ["bench", "cli", "--json", "--repeat", "1", "--robot-seconds", "0.5"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    for key in ("plugins_s", "robot_protocols_s", "version_s"):
        assert d[key] > 0, key
    assert d["meets_targets"]["plugins"] == (d["plugins_s"] < d["plugins_target_s"])
    rob = d["robot"]
    if "skipped" in rob:
        assert d["robot_realtime_factor"] is None
        return
    # one 0.5 s period streamed at 1 kHz: the last sample is at 0.499 s
    assert rob["device_s"] == pytest.approx(0.5, abs=2e-3) and rob["samples"] == 500
    assert d["robot_realtime_factor"] == pytest.approx(rob["device_s"] / rob["wall_s"])


def test_bench_page_names_command_version_machine_and_date(tmp_path):
    """--page writes the figures as a Markdown page headed by what measured them; stdout stays JSON."""
    from skinkit import __version__, jsonio

    page = tmp_path / "store.md"
    r = CliRunner().invoke(cli, ["bench", "store", "--blocks", "3", "--block", "50", "--json",
                                 "--page", str(page)])
    assert r.exit_code == 0, r.output
    res = jsonio.loads_strict(r.stdout)
    text = page.read_text(encoding="utf-8")
    head = text.split("```")[0]
    assert f"`skinkit bench store --blocks 3 --block 50 --json --page {page}`" in head
    assert f"skinkit {__version__}" in head and " UTC" in head
    for word in ("cores", "Python", "NumPy", "SciPy"):
        assert word in head, word
    assert "samples/s" in text and f"{res['samples']} samples" in text
    assert jsonio.loads_strict(text.split("```json")[1].split("```")[0]) == res


def test_bench_page_refused_before_the_run(tmp_path):
    r = CliRunner().invoke(cli, ["bench", "store", "--page", str(tmp_path / "no" / "p.md")])
    assert r.exit_code == 2 and r.stderr.startswith("error: --page") and r.stdout == ""


def test_results_page_tables_and_lines():
    import datetime as dt

    from skinkit.bench.results_page import render

    host = {"platform": "Linux", "cpu": "CPU", "cpu_count": 2, "memory_gb": 8.0, "python": "3.11",
            "numpy": "2", "scipy": "1", "load_average_1min": None}
    text = render("T", "skinkit bench x", {"a": float("nan")}, ["line one"], [(["c1", "c2"], [["1", "a|b"]])],
                  when=dt.datetime(2026, 1, 2, 3, 4, tzinfo=dt.timezone.utc), host=host)
    assert text.startswith("# T\n\nWritten by `skinkit bench x` (skinkit ")
    assert "on 2026-01-02 03:04 UTC" in text and "2 cores, 8 GB memory" in text
    assert "line one" in text and "| c1 | c2 |" in text and "| 1 | a\\|b |" in text
    assert '"a": null' in text
