"""Calibrate on the twin, notebook style (each `# %%` is a cell; VS Code, Spyder and
Jupytext run them one by one). Rehearses a short sampling run on the MuJoCo twin, calibrates
the joint offsets, sensor pose and plate from it, and validates the result with ISO 9283.

    python examples/calibrate_on_the_twin.py
"""
# %% A short sampling run on the twin: 60 samples, the realistic world, poses seed 0
import numpy as np

import planecal

run = planecal.rehearse(samples=60, seed=0)
print(run)

# %% The samples are in SI units: counts (N, 6), distance_m (N,), plate (N,)
s = run.samples
print(f"first sample: counts {s.counts[0]}, distance {s.distance_m[0]:.6f} m")

# %% Calibrate from the scene's nominal values (all parameters but delta1, delta6 free)
cal = planecal.calibrate(run)
print(cal)

# %% How close are the identified joint offsets to the twin's hidden truth?
err = cal.params.joint_offsets - run.truth.joint_offsets
print("offset error [mrad]:", np.array2string(err * 1e3, precision=4))

# %% Validate on the twin: ISO 9283 pose accuracy at the tool point, nominal vs calibrated
#    vs the twin's own true model (the floor)
val = planecal.validate(cal, run, cycles=5, gauge_repeats=3)
print(val)
