"""The sampling loop on the MuJoCo twin with collision checking: rehearsals that a
calibration turns back into the twin's hidden joint offsets, and an interrupted run that
resumes where the robot stopped."""
import numpy as np
import pytest
from test_sampling_fakes import DropAfter

from planecal.model.encoder import counts_to_joints
from planecal.estimation.fit import Problem, solve
from planecal.links.base import AlwaysEnabled
from planecal.io.samples import read_samples
from planecal.sampling import Driver, RunSettings, SamplingRun, load_sidecar
from planecal.model.scene import load_scene, nominal_params

twin_mod = pytest.importorskip("planecal.twin")
collision = pytest.importorskip("planecal.safety.collision")


@pytest.fixture(scope="module")
def scene():
    return load_scene("thesis_final")


@pytest.fixture(scope="module")
def world(scene):
    return collision.CollisionWorld(scene, clearance_m=0.01)


def rehearse(scene, world, out, n, seed, enable=None, twin=None, resume=False):
    twin = twin or twin_mod.Twin(scene, seed=seed)
    drv = Driver(twin, twin, enable or AlwaysEnabled(), scene.robot)
    st = RunSettings.from_sidecar(load_sidecar(out)) if resume else \
        RunSettings(scene="thesis_final", samples=n, seed=seed)
    stats = SamplingRun(drv, scene, st, out, world, resume=resume, background=True).run()
    return stats, twin


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rehearsal_recovers_the_true_offsets_within_3_sigma(scene, world, tmp_path, seed):
    out = tmp_path / "RUN.tsv"
    stats, twin = rehearse(scene, world, out, 150, seed)
    assert stats.status == "complete" and stats.samples == 150
    assert stats.max_step_counts <= 51
    s = read_samples(out)
    assert len(s) == 150
    fit = solve(Problem.from_samples(scene.robot, s, nominal_params(scene)))
    truth = twin.truth
    err = fit.params.joint_offsets[1:5] - truth.joint_offsets[1:5]
    sd = fit.std[1:5]
    assert np.all(np.isfinite(sd)) and np.all(sd > 0)
    print(f"seed {seed}: offsets 2..5 error [urad] {np.round(err * 1e6, 1)}, "
          f"std [urad] {np.round(sd * 1e6, 1)}, rms {fit.rms_mm() * 1e3:.1f} um, "
          f"rejected {stats.rejected}, robot {stats.robot_time_s:.0f} s, "
          f"wall {stats.wall_time_s:.1f} s")
    assert np.all(np.abs(err) < 3 * sd), (err, sd)
    # the nominal offsets (zero) were off by far more than that
    assert np.max(np.abs(truth.joint_offsets[1:5]) / sd) > 10
    # every sample was taken at a configuration the checker passes
    for qe in s.qe[::10]:
        assert world.check_config(counts_to_joints(scene.robot, qe)).ok


def test_interrupted_rehearsal_resumes_where_the_robot_stopped(scene, world, tmp_path):
    # the ticks after which the 2nd and the 3rd sample are taken, from uninterrupted runs
    t2 = rehearse(scene, world, tmp_path / "two.tsv", 2, 7)[0].ticks
    t3 = rehearse(scene, world, tmp_path / "three.tsv", 3, 7)[0].ticks
    drop = t2 + (t3 - t2) // 3  # on the way to the 3rd pose
    out = tmp_path / "RUN.tsv"
    stats1, twin1 = rehearse(scene, world, out, 6, 7, enable=DropAfter(drop))
    assert stats1.status == "stopped" and stats1.samples == 2  # mid-path to the 3rd
    assert twin1.ticks == drop  # nothing was sent after the enable signal dropped
    n1 = stats1.samples
    assert len(read_samples(out)) == n1
    # a new session: the twin (same truth) starts where the robot stopped
    twin2 = twin_mod.Twin(scene, seed=7, start_counts=twin1.current_counts)
    stats2, _ = rehearse(scene, world, out, 6, 7, twin=twin2, resume=True)
    assert stats2.status == "complete" and stats2.sessions == 2
    s = read_samples(out)
    assert len(s) == 6 and len({tuple(r) for r in s.qe}) == 6
    assert stats2.ticks == drop + twin2.ticks
