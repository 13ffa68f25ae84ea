"""The demo's results page carries figures: the diagnosis's per-sample series and per-point maps
stay in the summary and the gap report's JSON, not on the page."""

from __future__ import annotations

from skinkit.cli.demo import PER_SAMPLE, page_figures


def test_the_page_leaves_the_per_sample_arrays_to_the_gap_report() -> None:
    diag = {"named": ["prestress"], "shrinkage": {"overall": 0.6}, "files": ["gap/gap.json"],
            **{k: [[0.0] * 3] for k in PER_SAMPLE}}
    summary = {"times_s": {"diagnose": 1.0}, "diagnose": diag}
    page = page_figures(summary)
    assert page["diagnose"] == {"named": ["prestress"], "shrinkage": {"overall": 0.6},
                                "files": ["gap/gap.json"]}
    assert page["times_s"] == summary["times_s"]
    assert set(PER_SAMPLE) <= set(summary["diagnose"])      # the summary itself is left whole
    assert page_figures({"diagnose": None}) == {"diagnose": None}
