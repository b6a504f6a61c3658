"""planecal validate over several truths (issue 12 item 3): the realistic world against the
ideal one, the medians of the JSON against its per-truth rows, and what each error source
alone leaves after an offsets-only calibration (the breakdown)."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.base.errors import InputError
from planecal.studies.validation import (breakdown_variants, cannot_remove,
                                         summarize)

SMALL = ["--samples", "30", "--cycles", "3", "--gauge-repeats", "2", "--jobs", "1"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two truths of each world, 30 samples each (the figures below measured so)."""
    d = tmp_path_factory.mktemp("validate")
    out = {}
    for world in ("realistic", "ideal"):
        f = d / f"{world}.json"
        assert main(["validate", "--errors", world, "--truth-seeds", "0,1", "--breakdown",
                     "none", "--out", str(f)] + SMALL) == 0
        out[world] = json.loads(f.read_text())
    return out


@pytest.mark.parametrize("world", ["realistic", "ideal"])
def test_truths_and_their_medians(runs, world):
    v = runs[world]
    assert v["errors"] == world and v["level"] == "offsets"
    t = v["truths"]
    assert [r["truth_seed"] for r in t] == [0, 1]
    after = [r["ap_after_mm"] for r in t]
    before = [r["ap_before_mm"] for r in t]
    assert v["ap_after_median_mm"] == pytest.approx(np.median(after), rel=1e-12)
    assert v["ap_before_median_mm"] == pytest.approx(np.median(before), rel=1e-12)
    assert v["ap_after_worst_mm"] == max(after)
    assert v["worst_truth_seed"] == int(np.argmax(after))
    # the single-truth keys: the median truth's (the lower one of an even count)
    med = t[int(np.argmin(after))]
    assert v["median_truth_seed"] == v["detail_truth_seed"] == med["truth_seed"]
    for k in ("ap_before_mm", "ap_after_mm", "rp_mm", "gauge_error_before_mm",
              "gauge_error_after_mm"):
        assert v[k] == med[k]
    assert v["rp_mm"] == max(v["rp_before_mm"], v["rp_after_mm"])
    for r in t:
        assert r["samples"] == 30 and np.isfinite(r["gauge_error_after_mm"])


def test_ideal_world_keeps_its_bounds(runs):
    # the model is the world's structure: 30 samples leave a few 10 um of AP
    for r in runs["ideal"]["truths"]:
        assert r["ap_after_mm"] < 0.5 and r["ap_before_mm"] > 5 * r["ap_after_mm"]
        assert abs(r["gauge_error_after_mm"]) < 0.1
        assert r["max_model_error_mm"] < 0.03  # noise only (Table 9's real: 0.10-0.19)


def test_realistic_world_leaves_more_than_the_ideal_one(runs):
    real, ideal = runs["realistic"], runs["ideal"]
    # measured (30 samples): realistic AP after 2.48 and 1.30 mm, ideal below 0.1 mm
    assert real["ap_after_median_mm"] > 5 * ideal["ap_after_median_mm"]
    assert real["ap_after_median_mm"] > 0.3
    for r, i in zip(real["truths"], ideal["truths"]):
        assert r["ap_after_mm"] > i["ap_after_mm"]
        # the fit sees the model's mismatch: Table 9's range, not the noise's
        assert 0.08 < r["max_model_error_mm"] < 0.4
    # repeatability is the same robot's in both worlds (ISO RP, 3 cycles: loose)
    assert real["rp_after_median_mm"] < 0.15 and ideal["rp_after_median_mm"] < 0.15


def test_breakdown_each_source_alone(tmp_path):
    """Truth 0 with each source of the realistic profile alone: the noise-free cell is
    calibrated away, the geometry and the compliance are not."""
    f = tmp_path / "B.json"
    assert main(["validate", "--truth-seeds", "0", "--out", str(f), "--samples", "40",
                 "--cycles", "2", "--gauge-repeats", "1", "--jobs", "1"]) == 0
    bd = json.loads(f.read_text())["breakdown"]
    assert bd["mode"] == "alone" and bd["truth_seed"] == 0
    assert bd["sources"] == ["geometry", "compliance", "gear", "backlash", "noise",
                             "laser_linearity"]
    rows = {r["variant"]: r for r in bd["variants"]}
    none = rows["none (cell only)"]
    # only the cell's own parameters: the fit's model is the world's (no noise either)
    assert none["ap_after_mm"] < 0.05 and none["max_model_error_mm"] < 1e-3
    assert rows["geometry alone"]["ap_after_mm"] > 0.3
    assert rows["compliance alone"]["ap_after_mm"] > 0.2
    assert rows["noise alone"]["ap_after_mm"] < 0.08
    assert rows["all sources"]["ap_after_mm"] > 0.3
    # a share is that variant's AP after minus the cell-only world's, largest first
    cr = {c["source"]: c for c in bd["cannot_remove"]}
    for f_ in bd["sources"]:
        assert cr[f_]["ap_after_share_mm"] == pytest.approx(
            rows[f"{f_} alone"]["ap_after_mm"] - none["ap_after_mm"], abs=1e-12)
    shares = [c["ap_after_share_mm"] for c in bd["cannot_remove"]]
    assert shares == sorted(shares, reverse=True)
    assert bd["cannot_remove"][0]["source"] in ("geometry", "compliance")
    # planecal report reads it: the breakdown's figure and table
    assert main(["report", str(f), "--out", str(tmp_path / "rep")]) == 0
    html = (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
    assert "breakdown.png" in html and "What each error source leaves" in html


def test_report_over_truths(runs, tmp_path):
    f = tmp_path / "V.json"
    f.write_text(json.dumps(runs["realistic"]))
    assert main(["report", str(f), "--out", str(tmp_path / "rep")]) == 0
    html = (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
    assert "truths.png" in html and "realistic world, 2 truths" in html


def test_breakdown_variants_and_shares():
    v = breakdown_variants(["geometry", "gear", "noise"], "alone")
    assert v == [("all sources", ()), ("geometry alone", ("gear", "noise")),
                 ("gear alone", ("geometry", "noise")), ("noise alone", ("geometry", "gear")),
                 ("none (cell only)", ("geometry", "gear", "noise"))]
    off = breakdown_variants(["geometry", "gear"], "off")
    assert off[1] == ("without geometry", ("geometry",))
    with pytest.raises(InputError):
        breakdown_variants(["gear"], "some")
    bd = {"mode": "off", "sources": ["geometry", "gear"], "variants": [
        {"variant": "all sources", "ap_after_mm": 1.0},
        {"variant": "without geometry", "ap_after_mm": 0.25},
        {"variant": "without gear", "ap_after_mm": 0.875}]}
    cr = cannot_remove(bd)
    assert [(c["source"], c["ap_after_share_mm"]) for c in cr] == [("geometry", 0.75),
                                                                  ("gear", 0.125)]


def test_summarize_even_count_and_failed_truths():
    def r(seed, after):
        return {"truth_seed": seed, "ap_before_mm": 4.0, "ap_after_mm": after,
                "ap_before_cell_mm": 5.0, "ap_after_cell_mm": after + 1, "rp_mm": 0.05,
                "rp_before_mm": 0.05, "rp_after_mm": 0.04, "gauge_error_before_mm": -1.0,
                "gauge_error_after_mm": 0.1 * seed, "calibration": {}}
    s, med, worst = summarize([r(0, 0.8), r(1, 0.2), {"truth_seed": 2, "failed": "gave up"},
                               r(3, 0.5), r(4, 1.1)])
    assert s["ap_after_median_mm"] == pytest.approx(0.65)
    assert med["truth_seed"] == 3 and worst["truth_seed"] == 4
    assert s["failed_truths"] == [{"truth_seed": 2, "reason": "gave up"}]
    assert [t["truth_seed"] for t in s["truths"]] == [0, 1, 3, 4]
    assert s["gauge_error_after_worst_mm"] == pytest.approx(0.4)
    with pytest.raises(InputError, match="no truth could be validated"):
        summarize([{"truth_seed": 0, "failed": "gave up"}])


def test_level_and_seed_errors(capsys):
    assert main(["validate", "--level", "level3"]) == 2
    assert "--level" in capsys.readouterr().err
    assert main(["validate", "--truth-seeds", "0,0"]) == 2
    assert "argument --truth-seeds: the seed 0 is given twice" in capsys.readouterr().err
    assert main(["validate", "--truth-seed", "1", "--truth-seeds", "2"]) == 2
    assert main(["validate", "--errors", "nonesuch"]) == 2
    assert main(["validate", "--calibrated", "x.json"]) == 2


def test_validate_level_full_commands_the_whole_calibrated_model(tmp_path):
    """--level full on three plates in the realistic world: the JSON records the level; the
    full model (with J2/J3 compliance) places the ISO poses better than nominal by far, and
    its fit leaves a smaller max model error than offsets-only on the same samples."""
    out = {}
    for level in ("offsets", "full"):
        f = tmp_path / f"{level}.json"
        argv = ["validate", "--scene", "three_plates", "--truth-seed", "3", "--samples", "90",
                "--cycles", "3", "--gauge-repeats", "2", "--jobs", "1", "--breakdown", "none",
                "--level", level, "--out", str(f)]
        assert main(argv + (["--compliance"] if level == "full" else [])) == 0
        out[level] = json.loads(f.read_text())
    full, off = out["full"], out["offsets"]
    assert full["level"] == "full" and full["compliance"] is True and off["level"] == "offsets"
    t_full, t_off = full["truths"][0], off["truths"][0]
    assert t_full["ap_after_mm"] < t_full["ap_before_mm"] / 3
    assert t_full["max_model_error_mm"] < t_off["max_model_error_mm"]
