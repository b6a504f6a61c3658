"""A result is what its status says (issue 30 item 6): a fit that cannot identify what it
was asked, or did not converge, is never ``"status": "converged"`` in its file, and no
controller-file writer takes it (export in every format, urdf --params, compensate,
history rollback): one line, exit 2, nothing written, unless --force, which says on
stderr what it overrides. Before: the file said "converged" and ``urdf --params``
exported it."""
import json

import pytest

from planecal.cli import main


def _run(capsys, argv):
    capsys.readouterr()
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """25 samples (realistic world, seed 5): level nonkinematic cannot identify phi_y
    there (exit 1); one correction (--max-iter 1) does not converge; level offsets is a
    calibration. Each recorded in a history of its own folder."""
    d = tmp_path_factory.mktemp("status")
    run = d / "r.tsv"
    assert main(["rehearse", "--samples", "25", "--seed", "5", "--out", str(run), "-q"]) == 0
    out = {}
    for name, extra, code in (("unidentified", ["--level", "nonkinematic"], 1),
                              ("unconverged", ["--max-iter", "1"], 1),
                              ("good", [], 0)):
        out[name] = d / f"{name}.json"
        assert main(["calibrate", str(run), "--out", str(out[name]), "--history",
                     str(d / f"{name}.db"), "-q", *extra]) == code
    return d, out


def test_the_status_says_what_the_fit_did(results):
    _, out = results
    docs = {k: json.loads(p.read_text()) for k, p in out.items()}
    assert docs["unidentified"]["status"] == "not_identifiable"
    assert docs["unidentified"]["identifiability"]["not_identifiable"] == ["phi_y"]
    # 25 samples cannot determine level full's 35 candidates: its verdict is judged against
    # the simpler level the samples determine (before: the verdict's refit of level full
    # turned the calibration into an input error, exit 2)
    assert [c["level"] for c in docs["unidentified"]["verdict"]["comparisons"]] == ["offsets"]
    assert docs["unconverged"]["status"] == "max_iterations"
    assert docs["good"]["status"] == "converged"


@pytest.mark.parametrize("fmt", ["fd11", "offsets", "ur"])
def test_export_refuses_a_result_that_is_not_a_calibration(results, capsys, fmt):
    d, out = results
    for name, why in (("unidentified", "could not identify phi_y"),
                      ("unconverged", "did not converge")):
        dest = d / f"{name}.{fmt}"
        code, text, err = _run(capsys, ["export", str(out[name]), "--format", fmt,
                                        "--out", str(dest), "--no-history"])
        assert code == 2 and text == "" and not dest.exists()
        assert len(err.strip().splitlines()) == 1 and why in err and "--force" in err


def test_urdf_and_compensate_refuse_it_too(results, capsys):
    d, out = results
    dest = d / "u.urdf"
    code, _, err = _run(capsys, ["urdf", "--params", str(out["unidentified"]), "--out",
                                 str(dest)])
    assert code == 2 and "phi_y" in err and len(err.strip().splitlines()) == 1
    assert not dest.exists() and not (d / "u_meshes").exists()
    targets = d / "t.csv"
    targets.write_text("name,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\np,0,0,0,0,-30,0\n")
    code, _, err = _run(capsys, ["compensate", str(targets), "--params",
                                 str(out["unconverged"]), "--out", str(d / "c.tsv")])
    assert code == 2 and "did not converge" in err and not (d / "c.tsv").exists()


def test_history_rollback_refuses_it(results, capsys):
    d, _ = results
    dest = d / "rollback.json"
    code, _, err = _run(capsys, ["history", "rollback", "1", "--history",
                                 str(d / "unidentified.db"), "--out", str(dest)])
    assert code == 2 and "phi_y" in err and not dest.exists()


def test_force_writes_it_and_says_what_it_overrides(results, capsys):
    d, out = results
    dest = d / "forced.json"
    code, text, err = _run(capsys, ["export", str(out["unidentified"]), "--format",
                                    "offsets", "--out", str(dest), "--force",
                                    "--no-history"])
    assert code == 0 and dest.exists()
    assert "--force" in err and "could not identify phi_y" in err
    urdf = d / "forced.urdf"
    code, _, err = _run(capsys, ["urdf", "--params", str(out["unconverged"]), "--out",
                                 str(urdf), "--no-meshes", "--force"])
    assert code == 0 and urdf.exists() and "did not converge" in err


def test_a_calibration_is_exported(results, capsys):
    d, out = results
    dest = d / "good-offsets.json"
    code, _, err = _run(capsys, ["export", str(out["good"]), "--format", "offsets",
                                 "--out", str(dest), "--no-history"])
    assert code == 0 and dest.exists() and "--force" not in err


def test_the_refusal_is_one_function_a_reason_plugs_into(results, monkeypatch):
    """The reasons are ``REFUSALS``: a further one (a verdict's, say) is asked by every
    writer through ``CalibrationResult.refusal``."""
    from planecal.jobs import results as R
    _, out = results
    good = R.read_result(out["good"])
    assert good.refusal() is None
    monkeypatch.setattr(R, "REFUSALS", (*R.REFUSALS, lambda r: "a simpler level predicts "
                                        "better" if r.status == "converged" else None))
    assert good.refusal() == "a simpler level predicts better"
