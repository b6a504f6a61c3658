"""The parameter layout: names, units, groups, the --free parser, the vector <-> CellParams
codec, and the Jacobian's columns addressed by name."""
import numpy as np
import pytest

from conftest import SEED_QE
from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict, predict_with_jacobian
from planecal.base.errors import InputError
from planecal.model.layout import (ParamLayout, joint_offsets_group, level1_layout, plane_group,
                             sensor_angles_group, sensor_origin_group)

NAMES_2 = ["delta1", "delta2", "delta3", "delta4", "delta5", "delta6", "o_x", "o_y", "o_z",
           "phi_y", "phi_z", "n1_x", "n1_y", "n1_z", "n2_x", "n2_y", "n2_z"]


def _params(rng, k):
    return CellParams(rng.uniform(-5e-3, 5e-3, 6), [0.03, -0.07, 0.18],
                      rng.uniform(0.9, 1.5), rng.uniform(-1.2, -0.9),
                      np.tile([0.0, -1.0, 3.6], (k, 1)) + rng.uniform(-0.3, 0.3, (k, 3)))


def test_level1_names_units_groups():
    L = level1_layout(2)
    assert L.names == NAMES_2 and len(L) == 17 and L.n_planes == 2
    assert L.units == ["rad"] * 6 + ["m"] * 3 + ["rad"] * 2 + ["1/m"] * 6
    assert [g.name for g in L.groups] == ["joint_offsets", "sensor_origin", "sensor_angles",
                                          "plane1", "plane2"]
    assert L.names[L.slice("sensor_origin")] == ["o_x", "o_y", "o_z"]
    assert L.names[L.slice("sensor_angles")] == ["phi_y", "phi_z"]
    assert L.group("plane2").names == ["n2_x", "n2_y", "n2_z"]
    assert [L.names[c] for c in L.columns("plane")[1]] == ["n2_x", "n2_y", "n2_z"]
    assert L.index("phi_z") == 10 and list(L.indices(["n2_x", "delta1"])) == [14, 0]
    assert L.names_of(L.default_free) == [n for n in NAMES_2 if n not in ("delta1", "delta6")]
    # the display units and the practical limits of today's tables
    assert L.display("delta3") == (1e6, "urad") and L.display("phi_y") == (1e6, "urad")
    assert L.display("o_z") == (1e6, "um") and L.display("n2_y") == (1e3, "1e-3/m")
    assert list(L.practical_std(["delta2", "o_x", "phi_z", "n1_z"])) == [0.01, 0.01, 0.01, 0.1]
    assert level1_layout(2) is L  # built once per plate count


def test_groups_partition_the_vector():
    for k in (1, 2, 3):
        L = level1_layout(k)
        cols = np.concatenate([np.arange(len(L))[L.slice(g.name)] for g in L.groups])
        assert sorted(cols) == list(range(len(L)))  # every column once
        assert L.columns("plane").shape == (k, 3)
        np.testing.assert_array_equal(
            L.columns("plane").ravel(),
            np.concatenate([np.arange(len(L))[L.slice(f"plane{m + 1}")] for m in range(k)]))


def test_vector_order_is_the_saved_files_order_and_round_trips():
    rng = np.random.default_rng(1)
    for k in (1, 3):
        p = _params(rng, k)
        L = level1_layout(k)
        x = p.to_vector(L)
        # the order planecal has always used (seed 6.3): figures and files do not change
        np.testing.assert_array_equal(x, np.concatenate(
            [p.joint_offsets, p.sensor_origin, [p.phi_y, p.phi_z], p.planes.ravel()]))
        np.testing.assert_array_equal(p.to_vector(), x)
        back = CellParams.from_vector(x, L)
        np.testing.assert_array_equal(back.to_vector(L), x)
        assert back.phi_y == p.phi_y and back.n_planes == k
        y = rng.normal(size=len(L))
        np.testing.assert_array_equal(CellParams.from_vector(y, L).to_vector(L), y)
    with pytest.raises(ValueError, match="layout of 14"):
        CellParams.from_vector(np.zeros(17), level1_layout(1))


def test_free_parser():
    L = level1_layout(2)
    assert L.names_of(L.free_from_names("delta2, o_x,n2_z")) == ["delta2", "o_x", "n2_z"]
    assert L.names_of(L.free_from_names(["phi_y", "delta5"])) == ["delta5", "phi_y"]
    assert L.free_from_names("all").all()
    for default in (None, "", "  ", []):
        np.testing.assert_array_equal(L.free_from_names(default), L.default_free)
    with pytest.raises(InputError) as e:
        L.free_from_names("delta2,delta9")
    msg = str(e.value)
    assert "unknown parameter 'delta9'" in msg and "known: delta1, delta2" in msg \
        and msg.endswith("n2_z") and "\n" not in msg
    with pytest.raises(InputError, match="no parameter named"):
        L.free_from_names(" , ")
    with pytest.raises(InputError, match="unknown parameter 'n3_x'"):
        L.mask(["n3_x"])
    np.testing.assert_array_equal(L.mask(["delta1", "n1_x"]),
                                  np.isin(np.arange(17), [0, 11]))


def test_bad_layouts_are_refused():
    with pytest.raises(ValueError, match="names used twice"):
        ParamLayout([plane_group(0), plane_group(0)])
    with pytest.raises(ValueError, match="not numbered"):
        ParamLayout([joint_offsets_group(), plane_group(1)])
    with pytest.raises(ValueError):
        level1_layout(0)


def _fd_columns(robot, qe, params, pidx, L, h_rel=1e-6):
    x = params.to_vector(L)
    Jn = {}
    for name in L.names:
        j = L.index(name)
        h = h_rel * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        Jn[name] = (predict(robot, qe, CellParams.from_vector(xp, L), pidx)
                    - predict(robot, qe, CellParams.from_vector(xm, L), pidx)) / (2 * h)
    return Jn


@pytest.mark.parametrize("order", ["level1", "reversed"])
def test_jacobian_columns_by_name_against_central_differences(robot, order):
    # every column is filled once and right: each named column against central
    # differences of predict; a layout with the groups in another order gives the same
    # columns by name (nothing in the Jacobian knows an offset)
    rng = np.random.default_rng(8)
    k = 3
    params = _params(rng, k)
    L1 = level1_layout(k)
    L = L1 if order == "level1" else ParamLayout(
        [plane_group(2), sensor_angles_group(), plane_group(0), sensor_origin_group(),
         plane_group(1), joint_offsets_group()])
    qe = np.vstack([SEED_QE + rng.integers(-3000, 3000, (5, 6)) for _ in range(3)])
    pidx = np.repeat(np.arange(3), 5)
    d, J = predict_with_jacobian(robot, qe, params, pidx, L)
    np.testing.assert_allclose(d, predict(robot, qe, params, pidx), rtol=1e-14)
    Jn = _fd_columns(robot, qe, params, pidx, L)
    scale = np.abs(J).max()
    for name in L.names:
        col = J[:, L.index(name)]
        assert np.any(col != 0), name  # not left empty
        np.testing.assert_allclose(col, Jn[name], rtol=1e-6, atol=1e-9 * scale, err_msg=name)
    _, J1 = predict_with_jacobian(robot, qe, params, pidx, L1)
    for name in L.names:
        np.testing.assert_array_equal(J[:, L.index(name)], J1[:, L1.index(name)])
    # samples on plate m do not depend on another plate's n~
    for m in range(k):
        others = [c for g in L.groups_of("plane") if g.index != m for c in
                  range(len(L))[L.slice(g.name)]]
        assert np.all(J[pidx == m][:, others] == 0)
