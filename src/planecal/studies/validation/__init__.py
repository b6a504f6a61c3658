"""Validation on the twin (``settings``, ``iso9283``, ``gauge``, ``run``, ``truths``): ISO 9283 pose accuracy AP and repeatability RP (seed 3.2-3.3),
and the gauge-block test of seed 9.3, each with the nominal and the calibrated model, in a
world of the twin's error profile (``twin.profile``: the truth, the robot's true geometry,
the joint errors, the laser's), over several truths, and with each error source switched
off in turn (``breakdown``) to measure what an offsets-only calibration leaves of it.

ISO 9283 (position part). A cube with edges parallel to the base axes is placed over the
calibrated region: centred on the mean flange position of the calibration samples, edge
``cube_edge`` (default: 80 % of the samples' smallest flange-position range between the
10th and 90th percentiles, at most 0.25 m, shrunk by 0.75 until P1..P5 are reachable
and collision-free). Its diagonal plane through corners
(-,-,-), (+,+,-), (+,+,+), (-,-,+) holds P1 (the centre) and P2..P5, on the diagonals
at a tenth of the diagonal from the corners. The commanded orientation is the flange's at
the scene's calibration position. For each model (nominal: zero offsets; calibrated:
the fitted offsets) the controller converts the commanded pose to counts: IK with the
model's offsets (equivalently encoder.offsets_to_qe0) nearest to the calibration
position, then ``joints_to_counts``. The twin drives there as the robot does (the sampling
run's step path, ``sampling.driver``, each path collision-checked; a joint's backlash
follows the direction it came from) and settles (a fresh repeatability draw), and the
*true* attained position of the TCP (flange origin, or ``tcp`` in the flange frame) is read
from MuJoCo. ``cycles`` (30) cycles P1 -> P5. Per pose:
  AP = |barycentre of the attained positions - commanded position|
  RP = l_bar + 3 S_l,  l_j = |x_j - barycentre|, S_l their sample std.
Only the joint offsets enter AP: the sensor and planes are not part of the robot.

Two frames. ISO 9283 measures in the robot's base coordinate system: the measurement is
registered to the robot as it stands (``robot_frame``: the frame of joint 1 at its zero,
i.e. J1's axis, J1's zero direction and the height of that frame, which a laser tracker
finds from the robot's own first axis). AP (``ap_mm``) is in that frame. The cell frame
(``ap_cell_mm``) is the twin's world: what a program written in the nominal cell
coordinates reaches; it adds the robot's placement (the base frame error of a realistic
world) and J1's zero offset delta1, which no plane calibration can see (a turn about J1 or
a shift of the whole robot moves the plates with it). In the ideal world the two agree
unless delta1 is drawn (``offsets_all``).

Gauge block (9.3): a block of length L (default 100 mm) stands on the (true) plate at its
centre, its two measuring faces perpendicular to the plate and to the plate's x edge.
Four points on each face (a 20 x 20 mm square around the face centre, ``face_height``
above the plate) are measured by the laser with the beam pointing into the face, tilted
down towards the plate by ``tilt`` (sensor above the plate); the pose is chosen with the
nominal model (IK within limits, collision-free target in ``CollisionWorld``, which does
not know the block) and the twin measures: the true sensor pose (MuJoCo site, with the
repeatability draw of that pose) and a ray to the analytic face plane, plus the laser
noise of a 100-reading mean and the laser's linearity error of the world (``twin.ticks``'s
laser model). Each model turns (counts, distance) into a point
``o_b + d z_b``; a plane is fitted to each face's four points; the length is the mean
distance of each face's points from the other face's plane (both ways, averaged); its
error against L is reported for the nominal model (scene nominal sensor pose, zero
offsets), the calibrated model, and the calibrated sensor pose with nominal offsets
(to separate the offsets' share). ``gauge_repeats`` repetitions give mean and std.
The block is modelled analytically, not as MuJoCo geometry (that would need the scene
builder, owned elsewhere).

Over truths (``validate_truth``, a pure function of a ``TruthJob``): draw the world
(``studies.montecarlo.world_for``), sample a calibration set on that world's twin
(``twin_samples``: the sampling run's planner, collision checks and laser reads), calibrate
offsets-only from the nominal values (``fit.solve``), validate on the same world.
``calibrate_run`` is the one place the fit is called (``level`` 'offsets' today).
``summarize`` gives median and worst; ``breakdown`` repeats one truth with each error
family of ``montecarlo.SOURCES`` on alone (or switched off in turn) and reports AP after
calibration per variant: what each source leaves. The truths and the variants run on
``studies.distributed.Engine`` (``run_jobs``).
"""
from planecal.studies.validation.cube import (SamplePoses, default_edge, medoid, medoid_order,
                                              nearest_sample_m)
from planecal.studies.validation.gauge import (gauge_block, gauge_block_geometry, gauge_length,
                                               laser_reading_mm, length_from, predicted_spread)
from planecal.studies.validation.iso9283 import (IsoPlan, Mover, ap_rp, iso9283, iso_points,
                                                 plan_iso, robot_frame)
from planecal.studies.validation.run import CUBE_RULE, figures, named_tcps, validate
from planecal.studies.validation.settings import (ANCHORS, FIGURE_KEYS, FORMAT, OLD_FORMATS,
                                                  ROLES, WHERE, ValidationSettings,
                                                  figure_keys)
from planecal.studies.validation.truths import (BREAKDOWN_KEYS, LEVEL_KEYS, TRUTH_KEYS,
                                                TruthJob, breakdown, breakdown_variants,
                                                cannot_remove, levels_beside, run_jobs,
                                                summarize, truth_row, truth_run,
                                                validate_truth)

__all__ = ["ANCHORS", "BREAKDOWN_KEYS", "CUBE_RULE", "FIGURE_KEYS", "FORMAT", "IsoPlan",
           "LEVEL_KEYS", "Mover", "OLD_FORMATS", "ROLES", "SamplePoses", "TRUTH_KEYS",
           "TruthJob", "ValidationSettings", "WHERE", "ap_rp", "breakdown",
           "breakdown_variants", "cannot_remove", "default_edge", "figure_keys", "figures",
           "gauge_block", "gauge_block_geometry", "gauge_length", "iso9283", "iso_points",
           "laser_reading_mm", "length_from", "levels_beside", "medoid", "medoid_order",
           "named_tcps",
           "nearest_sample_m", "plan_iso", "predicted_spread", "robot_frame", "run_jobs",
           "summarize", "truth_row", "truth_run", "validate", "validate_truth"]
