"""Compensation on the twin over truths (docs/COMPENSATE.md): python scripts/study_compensate.py ideal|realistic SCENE SEEDS
(e.g. realistic thesis_final 0,1,2,3,4). One line per truth: AP medians/max [mm] in the
robot frame (cell frame in brackets), nominal vs compensated, unseen targets and ISO P1..P5."""
import sys
import time
from planecal.model.scene import load_scene, nominal_params
from planecal.studies.rehearsal import RehearsalSettings, twin_samples
from planecal.estimation.calibrate import calibrate
from planecal.estimation.compensate import CalibratedModel
from planecal.safety.collision import CollisionWorld
from planecal.studies.compensation import compensation_study
errors, sc, seeds = sys.argv[1], sys.argv[2], [int(x) for x in sys.argv[3].split(",")]
scene = load_scene(sc)
checker = CollisionWorld(scene)
for s in seeds:
    t0 = time.time()
    st = RehearsalSettings(scene=sc, samples=150, errors=errors, truth_seed=s)
    world, opts = st.world(0)
    qe, d, plate, _ = twin_samples(scene, world, st, 100 + s, opts)
    fit = calibrate(scene.robot, qe, d, nominal_params(scene), plate).result
    r = compensation_study(scene, world, opts, CalibratedModel(scene.robot, fit.params), qe, n_targets=30, cycles=10, seed=s, checker=checker)
    keys = ["validation_nominal", "validation_compensated", "iso_nominal", "iso_compensated"]
    print(errors, sc, s, " | ".join(f"{k}: med {r[k+'_median_mm']:.3f} max {r[k+'_max_mm']:.3f} (cell med {r[k+'_cell_median_mm']:.3f})" for k in keys), f"conv {r['converged']} round {r['rounded_residual_max_mm']:.3f} {time.time()-t0:.1f}s", flush=True)
