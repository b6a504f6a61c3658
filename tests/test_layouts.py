"""planecal layouts (issue 13 item 5): the base-set selection (the calibration's own,
``estimation.identifiability.select_base``) on known matrices and against an SVD of a
finite-difference Jacobian of the distance model on 1 and 3 plates; the study's figures;
the three-plate scene reachable by an MC70 from collision-free poses with the laser in its
window (MuJoCo's own ray, not the model)."""
import json

import numpy as np
import pytest

from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict
from planecal.cli import main
from planecal.safety.collision import CollisionWorld
from planecal.model.encoder import joints_to_counts
from planecal.model.layout import level1_layout
from planecal.model.ik import ik_all
from planecal.model.scene import load_scene, nominal_params
from planecal.estimation.calibrate import CalibrationSettings
from planecal.estimation.identifiability import select_base
from planecal.studies.layouts import layout_study, subscene, subsets
from planecal.studies.planning import candidates


@pytest.fixture(scope="module")
def three():
    scene = load_scene("three_plates")
    return scene, CollisionWorld(scene)


def test_base_set_on_a_known_matrix():
    # five columns of a level-1 layout: scales must not matter; one a combination of two
    # others, one zero
    L = level1_layout(1)
    names = ["delta2", "delta3", "delta4", "delta5", "o_x"]
    rng = np.random.default_rng(0)
    A = rng.normal(size=(50, 3)) * [1.0, 1e3, 1e-3]
    J = np.zeros((50, len(L)))
    for n, c in zip(names, [A[:, 0], A[:, 1], A[:, 2], 2 * A[:, 0] - 5e3 * A[:, 2],
                            np.zeros(50)]):
        J[:, L.index(n)] = c
    bs = select_base(J, L, L.mask(names))
    why = {e.parameter: e for e in bs.excluded}
    assert bs.rank == 3 and why["o_x"].reason == "no_effect"
    assert len(bs.base) == 3 and "delta3" in bs.base
    # the excluded one of {delta2, delta4, delta5} is a stated combination of the other two
    (x,) = [k for k, e in why.items() if e.reason == "combination"]
    col = {n: J[:, L.index(n)] for n in names}
    got = sum(c * col[k] for k, c in why[x].combination.items())
    assert np.allclose(got, col[x], rtol=1e-9, atol=1e-12)


def _fd_jacobian(robot, qe, params, plate, layout, h=1e-7):
    x0 = params.to_vector(layout)
    cols = []
    for i in range(len(x0)):
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        cols.append((predict(robot, qe, CellParams.from_vector(xp, layout), plate)
                     - predict(robot, qe, CellParams.from_vector(xm, layout), plate)) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("plates", [(0,), (0, 1, 2)])
def test_identifiable_set_agrees_with_an_svd_of_a_finite_difference_jacobian(three, plates):
    scene, checker = three
    sub = subscene(scene, plates)
    qe, plate = [], []
    for k, i in enumerate(plates):
        c, _, _ = candidates(subscene(scene, (i,)), 40, i, checker)
        qe.append(c)
        plate.append(np.full(len(c), k))
    qe, plate = np.vstack(qe), np.concatenate(plate)
    layout = level1_layout(len(plates))
    free = layout.free_from_names("all")
    from planecal.model.measurement import predict_with_jacobian
    _, J = predict_with_jacobian(scene.robot, qe, nominal_params(sub), plate, layout)
    bs = select_base(J, layout, free)
    excluded = {e.parameter: e for e in bs.excluded}
    Jfd = _fd_jacobian(scene.robot, qe, nominal_params(sub), plate, layout)[:, free]
    A = Jfd / np.linalg.norm(Jfd, axis=0)
    s = np.linalg.svd(A, compute_uv=False)
    rank_fd = int(np.sum(s / s[0] > 1e-6))
    # the model loses exactly two directions on any plate layout: delta1 (a turn of the
    # plates about J1) and delta6 (a roll of the sensor, the same as phi_z and o_x, o_y)
    assert bs.rank == rank_fd == len(layout.names) - 2
    assert s[rank_fd - 1] / s[0] > 1e-4 and s[rank_fd] / s[0] < 1e-8
    names = layout.names_of(free)
    base = [names.index(n) for n in bs.base]
    sb = np.linalg.svd(A[:, base], compute_uv=False)
    assert sb[-1] / sb[0] > 1e-4  # the base set's FD columns are independent
    for name, e in excluded.items():  # each excluded FD column is its combination
        assert e.reason == "combination"
        col = Jfd[:, names.index(name)]
        fit = sum(c * Jfd[:, names.index(k)] for k, c in e.combination.items())
        assert np.linalg.norm(fit - col) < 1e-5 * np.linalg.norm(col)
    for name, e in excluded.items():  # each lost direction is delta1's or delta6's family
        assert {"delta1", "delta6"} & ({name} | set(e.combination))


def test_layout_study_figures(three):
    scene, checker = three
    res = layout_study(scene, CalibrationSettings(), samples=150, seed=0, checker=checker)
    rows = {"+".join(r["plates"]): r for r in res["layouts"]}
    # 1, 2 and 3 of its four plates (three plates and the stepped block's top)
    assert len(rows) == 14
    assert [len(r["plates"]) for r in res["layouts"]] == [1] * 4 + [2] * 6 + [3] * 4
    for r in rows.values():  # the default free set (delta1, delta6 fixed) is identifiable
        assert r["excluded"] == [] and r["rank"] == len(r["free"]) == 9 + 3 * len(r["plates"])
        assert r["samples"] == 150
    # measured (seed 0): delta2 72.5 urad on the thesis plate alone (its known weakness,
    # rho -0.97 with n1_x), 4.8 urad on all three plates
    a, abc = rows["plate_a"]["std"], rows["plate_a+plate_b+plate_c"]["std"]
    assert 50e-6 < a["delta2"] < 100e-6 and abc["delta2"] < 8e-6
    assert abc["delta2"] < a["delta2"] / 8
    for k in ("delta3", "delta4", "delta5"):
        assert abc[k] < 30e-6
    # plate_a's draws are the same in every subset that holds it
    assert rows["plate_a+plate_b"]["samples"] == 150


def test_free_all_names_the_lost_directions(three, capsys, tmp_path):
    out = tmp_path / "l.json"
    assert main(["layouts", "--samples", "60", "--free", "all", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "plate_a: rank 12 of 14" in text and "a combination of others" in text
    doc = json.loads(out.read_text())
    assert doc["format"] == "planecal-layouts/1" and len(doc["layouts"]) == 14
    assert all(r["rank"] == len(r["free"]) - 2 for r in doc["layouts"])
    assert main(["layouts", "--samples", "30", "--out", str(out)]) == 0  # its own: replaced
    (tmp_path / "x.json").write_text("{}")
    assert main(["layouts", "--out", str(tmp_path / "x.json")]) == 2
    assert main(["layouts", "--free", "nope"]) == 2


def test_subsets():
    assert subsets(3) == [(0,), (1,), (2,), (0, 1), (0, 2), (1, 2), (0, 1, 2)]
    assert subsets(1) == [(0,)]


# ----- the three-plate scene: reachable by a real MC70 -----------------------------------------

def _spot_poses(gen, frame, spot, rng, tries=400):
    """Sensor poses aiming at ``spot`` (plate coordinates) within the scene's cone,
    distance window and any roll, as flange poses."""
    x, y, z, c = frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3]
    p = c + spot[0] * x + spot[1] * y
    for _ in range(tries):
        t = np.radians(rng.uniform(0, gen.settings.cone_deg))
        az, psi = rng.uniform(0, 2 * np.pi, 2)
        d = rng.uniform(*gen.settings.distance_mm) * 1e-3
        b = -np.cos(t) * z + np.sin(t) * (np.cos(az) * x + np.sin(az) * y)
        x0 = x - (x @ b) * b
        x0 /= np.linalg.norm(x0)
        T = np.eye(4)
        T[:3, 0] = np.cos(psi) * x0 + np.sin(psi) * np.cross(b, x0)
        T[:3, 1] = np.cross(b, T[:3, 0])
        T[:3, 2] = b
        T[:3, 3] = p - d * b
        yield T @ gen.T_sf


@pytest.fixture(scope="module")
def reach(three):
    """(scene, pose generator, ``clear_hit(q, k)``): whether the collision checker clears
    q (10 mm) and the laser at q -- MuJoCo's ray on the exact twin -- hits plate k within
    its window."""
    from planecal.sampling.poses import PoseGenerator, PoseSettings
    from planecal.twin import Twin, TwinOptions
    scene, checker = three
    twin = Twin(scene, truth="nominal", options=TwinOptions.exact())
    gen = PoseGenerator(scene, PoseSettings(cone_deg=scene.cone_deg,
                                            distance_mm=tuple(scene.distance_mm)))
    lo, hi = scene.laser_range_mm

    def clear_hit(q, k) -> bool:
        if not checker.check_config(q).ok:
            return False
        twin.set_counts(joints_to_counts(scene.robot, q))
        h = twin.hit()
        return h.plate == k and lo <= h.distance_m * 1e3 <= hi
    return scene, gen, clear_hit


def test_every_plate_of_three_plates_is_reachable_from_clear_poses(reach):
    """A 3 x 3 grid of spots on each plate (30 mm from the edges, as the scene states):
    each spot is hit by the laser -- MuJoCo's ray on the twin at those counts, within the
    laser window -- from a pose within the MC70's joint limits that the collision checker
    clears (10 mm clearance)."""
    scene, gen, clear_hit = reach
    rng = np.random.default_rng(0)
    for k, plate in enumerate(scene.plates):
        for u in np.linspace(0.03, plate.size[0] - 0.03, 3):
            for v in np.linspace(0.03, plate.size[1] - 0.03, 3):
                found = any(clear_hit(q, k)  # ik_all: within the joint limits
                            for Tf in _spot_poses(gen, gen.frames[k], (u, v), rng)
                            for q in ik_all(scene.robot, Tf))
                assert found, f"{plate.name}: spot ({u:.3f}, {v:.3f}) m not reachable"


def test_three_plates_random_draws_mostly_reachable(reach):
    """The sampling run's own draws: measured 95-99.5 % of them have a clear pose whose
    beam hits the plate in the window (100 draws per plate); plate_a's far part is shadowed
    by the stepped block behind it (64 of 100), plate_d, the block's top, 80-85 of 100."""
    scene, gen, clear_hit = reach
    rng = np.random.default_rng(0)
    least = {"plate_a": 55, "plate_d": 70}
    for k, plate in enumerate(scene.plates):
        ok = sum(any(clear_hit(q, k) for q in gen.branch_targets(gen.draw(rng, k),
                                                                 scene.calibration_q))
                 for _ in range(100))
        assert ok >= least.get(plate.name, 90), f"{plate.name}: {ok} of 100 draws reachable"


@pytest.mark.parametrize("plates", [(0, 1), (0, 1, 2)])
def test_candidates_take_every_plate_in_turn(three, plates):
    """Each draw offers both wrist branches (two candidates): the plate goes round by draw,
    not by candidate (by candidate every draw of a 2-plate scene fell on its first plate)."""
    scene, checker = three
    _, _, plate = candidates(subscene(scene, plates), 60, 3, checker)
    counts = np.bincount(plate, minlength=len(plates))
    assert len(plate) == 60 and counts.min() >= 60 // len(plates) // 2, counts


def test_the_table_fits_the_terminal(three, capsys, monkeypatch):
    # issue 33: fourteen layouts made lines of up to 277 characters; now no line is longer
    # than the terminal (COLUMNS, as shutil reads it) or 100 when it is not a terminal, and
    # each table repeats the parameter and its unit
    for columns, width in ((None, 100), ("72", 72)):
        if columns:
            monkeypatch.setenv("COLUMNS", columns)
        else:
            monkeypatch.delenv("COLUMNS", raising=False)
        assert main(["layouts", "--samples", "20"]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert max(map(len, lines)) <= width, max(lines, key=len)
        heads = [ln for ln in lines if ln.startswith("parameter  unit")]
        assert len(heads) >= 2 and sum(ln.count("plate_") for ln in heads) == 4 + 2 * 6 + 3 * 4
        assert any(ln.startswith("delta2     urad ") for ln in lines)
