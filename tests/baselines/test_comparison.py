"""The paper's ordering on paper-like noise: CPO + HWC beats PnP, stereo and the single view."""

from __future__ import annotations

from vfactor.paper_comparison import run, summarise, table_one, table_two, tables


def test_cpo_beats_the_other_baselines_on_paper_like_noise():
    summary = summarise(run("paper_webots", frames=10, seed=0, methods=("cpo", "pnp", "stereo", "single_view")))
    assert all(s["count"] == 10 and s["failures"] == 0 for s in summary.values())
    cpo = summary["cpo"]["keypoint_cm"]
    for other in ("pnp", "stereo", "single_view"):
        assert cpo < 0.6 * summary[other]["keypoint_cm"], (other, summary[other]["keypoint_cm"], cpo)
    assert summary["cpo"]["translation_cm"] < min(summary[m]["translation_cm"] for m in ("pnp", "stereo", "single_view"))
    text = tables(summary)
    assert text.count("\n| cpo |") == 3


def test_paper_tables_have_the_papers_layout():
    rows = run("paper_webots", frames=6, seed=1, methods=("factor_graph", "cpo", "single_view", "pnp", "stereo"))
    one = table_one(rows)
    assert one.count("| lincoln_mkz |") == 5 and "P12" in one
    two = table_two(summarise(rows))
    assert two.splitlines()[0].startswith("| method | rotation (deg) | translation (cm)")
