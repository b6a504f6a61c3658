"""planecal validate over several truths (issue 12 item 3): the realistic world against the
ideal one, the medians of the JSON against its per-truth rows, and what each error source
alone leaves after an offsets-only calibration (the breakdown)."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.base.errors import InputError
from planecal.studies.validation import (FIGURE_KEYS, breakdown_variants, cannot_remove,
                                         levels_beside, summarize)

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
    assert v["format"] == "planecal-validate/3"
    assert v["errors"] == world and v["level"] == "offsets"
    t = v["truths"]
    assert [r["truth_seed"] for r in t] == [0, 1]
    after = [r["ap_after_tool_mm"] for r in t]
    assert v["ap_after_tool_median_mm"] == pytest.approx(np.median(after), rel=1e-12)
    assert v["ap_after_tool_worst_mm"] == max(after)
    assert v["worst_truth_seed"] == int(np.argmax(after))
    for key in FIGURE_KEYS:  # every figure says where and whose, with its median
        vals = [r[key] for r in t]
        assert all(x is not None for x in vals), key  # both cubes, every role measured
        assert v[key[:-3] + "_median_mm"] == pytest.approx(np.median(vals), rel=1e-12), key
    # the single-truth keys: the median truth's (the lower one of an even count)
    med = t[int(np.argmin(after))]
    assert v["median_truth_seed"] == v["detail_truth_seed"] == med["truth_seed"]
    for k in (*FIGURE_KEYS, "gauge_error_before_mm", "gauge_error_after_mm"):
        assert v[k] == med[k]
    # at level offsets there is no lower level: the one level is the validated one
    assert [r["level"] for r in v["levels"]] == ["offsets"]
    assert v["levels"][0]["ap_after_tool_mm"] == v["ap_after_tool_mm"]
    assert [r["level"] for r in v["levels_summary"]] == ["offsets"]
    for r in t:
        assert r["samples"] == 30 and np.isfinite(r["gauge_error_after_mm"])
        assert len(r["nearest_sample_mm"]) == 5 and r["nearest_sample_mm"][0] == 0.0


def test_ideal_world_keeps_its_bounds(runs):
    # the model is the world's structure: 30 samples leave a few 10 um of AP
    for r in runs["ideal"]["truths"]:
        assert r["ap_after_tool_mm"] < 0.5 and r["ap_before_tool_mm"] > 5 * r["ap_after_tool_mm"]
        # the world is the fit's model: the flange frame is robot.json's, so the flange
        # and the tool point agree within the sensor pose's error (measured 1-30 um)
        assert abs(r["ap_after_flange_mm"] - r["ap_after_tool_mm"]) < 0.1
        assert abs(r["gauge_error_after_mm"]) < 0.1
        assert r["max_model_error_mm"] < 0.03  # noise only (Table 9's real: 0.10-0.19)


def test_realistic_world_leaves_more_than_the_ideal_one(runs):
    real, ideal = runs["realistic"], runs["ideal"]
    # measured (30 samples): realistic AP after 2.48 and 1.30 mm, ideal below 0.1 mm
    assert real["ap_after_tool_median_mm"] > 5 * ideal["ap_after_tool_median_mm"]
    assert real["ap_after_tool_median_mm"] > 0.3
    for r, i in zip(real["truths"], ideal["truths"]):
        assert r["ap_after_tool_mm"] > i["ap_after_tool_mm"]
        # the floor: the twin's own true model leaves backlash and noise, far below the
        # calibration's AP in the realistic world, the noise alone in the ideal one
        assert r["ap_oracle_tool_mm"] < 0.3 * r["ap_after_tool_mm"]
        assert i["ap_oracle_tool_mm"] < 0.08
        # the fit sees the model's mismatch: Table 9's range, not the noise's
        assert 0.08 < r["max_model_error_mm"] < 0.4
    # repeatability is the same robot's in both worlds (ISO RP, 3 cycles: loose)
    assert real["rp_after_tool_median_mm"] < 0.15 and ideal["rp_after_tool_median_mm"] < 0.15


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
    assert none["ap_after_tool_mm"] < 0.05 and none["max_model_error_mm"] < 1e-3
    assert rows["geometry alone"]["ap_after_tool_mm"] > 0.3
    assert rows["compliance alone"]["ap_after_tool_mm"] > 0.2
    assert rows["noise alone"]["ap_after_tool_mm"] < 0.08
    assert rows["all sources"]["ap_after_tool_mm"] > 0.3
    # the twin's own true model knows the backlash (by each pose's approach direction):
    # with it alone it leaves the whole counts, as in the cell-only world (measured 17 and
    # 22 um); the offsets' floor leaves the backlash the offsets cannot model
    assert rows["backlash alone"]["ap_oracle_tool_mm"] < 0.03
    assert none["ap_oracle_tool_mm"] < 0.03
    assert rows["backlash alone"]["ap_floor_tool_mm"] > 2 * none["ap_floor_tool_mm"]
    # the noise apart: the same poses without it; its share is all minus all but it
    quiet = rows["all but the noise"]
    assert quiet["off"] == ["noise"] and quiet["ap_after_tool_mm"] > 0.3
    # a share is that variant's AP after minus the cell-only world's, largest first; the
    # noise's is not among them, and offsets model none of the sources
    cr = {c["source"]: c for c in bd["cannot_remove"]}
    assert "noise" not in cr and bd["modelled"] == []
    for f_ in bd["sources"]:
        if f_ != "noise":
            assert cr[f_]["ap_after_tool_share_mm"] == pytest.approx(
                rows[f"{f_} alone"]["ap_after_tool_mm"] - none["ap_after_tool_mm"],
                abs=1e-12)
            assert not cr[f_]["modelled"]
    shares = [c["ap_after_tool_share_mm"] for c in bd["cannot_remove"]]
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
    assert v == [("all sources", ()), ("all but the noise", ("noise",)),
                 ("geometry alone", ("gear", "noise")),
                 ("gear alone", ("geometry", "noise")), ("noise alone", ("geometry", "gear")),
                 ("none (cell only)", ("geometry", "gear", "noise"))]
    off = breakdown_variants(["geometry", "gear"], "off")
    assert off[1] == ("without geometry", ("geometry",))
    with pytest.raises(InputError):
        breakdown_variants(["gear"], "some")
    bd = {"mode": "off", "sources": ["geometry", "gear"], "variants": [
        {"variant": "all sources", "ap_after_tool_mm": 1.0},
        {"variant": "without geometry", "ap_after_tool_mm": 0.25},
        {"variant": "without gear", "ap_after_tool_mm": 0.875}]}  # a world without noise
    cr = cannot_remove(bd)
    assert [(c["source"], c["ap_after_tool_share_mm"]) for c in cr] == [("geometry", 0.75),
                                                                       ("gear", 0.125)]


def test_summarize_even_count_and_failed_truths():
    def r(seed, after):
        row = {k: 0.05 if k.startswith("rp") else 4.0 for k in FIGURE_KEYS}
        row.update(truth_seed=seed, ap_after_tool_mm=after, gauge_error_before_mm=-1.0,
                   gauge_error_after_mm=0.1 * seed, calibration={},
                   levels=[{"level": "offsets", "ap_after_tool_mm": after + 0.5,
                            "ap_after_flange_mm": 1.0, "ap_after_tool_cell_mm": 2.0,
                            "rp_after_tool_mm": 0.05},
                           {"level": "full", "ap_after_tool_mm": after,
                            "ap_after_flange_mm": 1.0, "ap_after_tool_cell_mm": 2.0,
                            "rp_after_tool_mm": 0.05}])
        return row
    s, med, worst = summarize([r(0, 0.8), r(1, 0.2), {"truth_seed": 2, "failed": "gave up"},
                               r(3, 0.5), r(4, 1.1)])
    assert s["ap_after_tool_median_mm"] == pytest.approx(0.65)
    assert med["truth_seed"] == 3 and worst["truth_seed"] == 4
    assert s["failed_truths"] == [{"truth_seed": 2, "reason": "gave up"}]
    assert [t["truth_seed"] for t in s["truths"]] == [0, 1, 3, 4]
    assert s["gauge_error_after_worst_mm"] == pytest.approx(0.4)
    lv = {x["level"]: x for x in s["levels_summary"]}
    assert lv["offsets"]["ap_after_tool_median_mm"] == pytest.approx(1.15)
    assert lv["full"]["ap_after_tool_worst_mm"] == pytest.approx(1.1)
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


def test_validate_level_full_commands_every_level_on_the_same_poses(tmp_path):
    """--level full --compliance on three plates in the realistic world: offsets-only and
    full + compliance calibrated from the same samples and commanded on the same ISO poses
    beside the nominal model and the twin's own true model; the full model fits the plates
    better, places the tool far better than nominal, and the floor lies below both."""
    f = tmp_path / "full.json"
    assert main(["validate", "--scene", "three_plates", "--truth-seed", "3", "--samples",
                 "90", "--cycles", "3", "--gauge-repeats", "2", "--jobs", "1", "--breakdown",
                 "none", "--level", "full", "--compliance", "--out", str(f)]) == 0
    v = json.loads(f.read_text())
    assert v["level"] == "full" and v["compliance"] is True
    assert v["model_after"] == "full + compliance"
    off, full = v["levels"]
    assert off["level"] == "offsets" and full["level"] == "full + compliance"
    assert full["ap_after_tool_mm"] == v["ap_after_tool_mm"]
    assert set(v["iso"]["models"]) == {"nominal", "offsets", "full + compliance",
                                       "floor: offsets", "floor: full + compliance", "oracle"}
    # each level's floor lies below the level's calibration and above the oracle
    for r in v["levels"]:
        assert v["ap_oracle_tool_mm"] < r["ap_floor_tool_mm"] < r["ap_after_tool_mm"], r
    assert full["ap_after_tool_mm"] < v["ap_before_tool_mm"] / 3
    assert full["max_model_error_mm"] < off["max_model_error_mm"]
    assert v["ap_oracle_tool_mm"] < min(off["ap_after_tool_mm"], full["ap_after_tool_mm"])
    t = v["truths"][0]
    assert [r["level"] for r in t["levels"]] == ["offsets", "full + compliance"]


def test_the_lower_levels_beside_a_level():
    from planecal.estimation.calibrate import CalibrationSettings
    from planecal.model.levels import LEVELS
    full = CalibrationSettings(level="full", compliance=True, free_scale=True)
    got = levels_beside(full)
    assert [s.label for s in got] == ["offsets", "full + compliance"] and got[-1] is full
    assert [s.label for s in levels_beside(CalibrationSettings())] == ["offsets"]
    top = CalibrationSettings(level=LEVELS[-1])  # whatever level the model has last
    assert [s.level for s in levels_beside(top)] == list(LEVELS)
