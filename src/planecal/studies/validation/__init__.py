"""Validation on the twin (``settings``, ``cube``, ``commanders``, ``floors``, ``iso9283``,
``gauge``, ``run``, ``truths``): ISO 9283 pose accuracy AP and repeatability RP (seed
3.2-3.3) where the tool is, in two cubes, and the gauge-block test of seed 9.3, in a world
of the twin's error profile (``twin.profile``: the truth, the robot's true geometry, the
joint errors, the laser's), over several truths, and with each error source switched off
in turn or on alone, the noise apart (``breakdown``).

Where AP is measured. The tool point is the laser's beam point at its measuring centre
(``Scene.standoff_m``: the middle of its window, 80 mm for the ZS-LD80). ISO 9283's P1..P5
are tool points in the robot's frame, and each model commands *its own estimate* of the
tool point onto them, the flange at one orientation ``R``: the nominal model with the
scene's sensor pose, a calibration with its calibrated sensor origin and beam angles. The
twin attains its *true* tool point (MuJoCo's laser site: the truth's sensor pose on the
true flange). Beside it, from the same motions, the flange (each model's commanded flange
position against the true flange: a plane calibration puts the flange frame's error into
the sensor pose, so it shows here and not at the tool point) and each named TCP (the
scene's ``tools``, ``--tcp-mm``'s ``tcp``: for them a calibration has no better estimate
than the nominal one). Keys say where and whose: ``ap_{before,after,oracle}_{tool,flange}
[_cell]_mm``, ``rp_..._mm``, worst of P1..P5 (``settings.figure_keys``).

Who commands (``commanders``), all on the same poses of a truth, one after the other:
the nominal model; each calibration (``compensate.CalibratedModel``: a validation at a
level also calibrates each level below it on the same samples, ``truths.levels_beside``);
each level's floor (``floors``: the level's own model with the parameters that put the
twin's true tool point best over the samples' poses, noise-free: the best any calibration
of that level can do, what it leaves being what the level does not model, repeatability
and whole counts); and the oracle, the twin's own whole true model
(``twin.oracle.TrueModel``: true offsets, geometry with base and flange frames, compliance
with the payload, gear error, backlash on the flank of each pose's approach direction, the
true sensor pose, solved for counts by the twin's own joint map and MuJoCo): the floor of a
model that knows every source, leaving repeatability and the rounding to whole counts. In
the realistic world level 3's model holds every source, so its floor and the oracle agree
(two codes: the calibration's model and the twin's). The calibrated models command through
the closed-form IK with their offsets, then Newton on the whole model
(``compensate.solve_poses``), registered on the robot's frame as ``compensate`` does. Each
pose's approach direction per joint is what the robot's counts show in one unmeasured
cycle P1..P5, P1 of that model's poses (``iso9283.observe_directions``: the straight
path's sign is not always the step path's last motion); the models with backlash (level 3,
its floor, the oracle) command again with it until it holds.

Two cubes (``cube``). ISO 9283's own (``cube.STANDARD_RULE``, keys ``..._standard_...``):
the largest cube with edges parallel to the robot's axes inside the region the cell's work
uses, here the samples' flange hull (a linear program over its facets), at the flange
orientation of one of the samples nearest its centre, shrunk by 0.75 where a pose is not
reachable, collision-free or inside the samples' joint ranges + 2 deg; its size and its
points' distances from the samples are reported. The near-sample cube (the keys without an
infix; ``cube.NEAR_RULE``): edges parallel to the robot's axes, centred on the
tool point of the samples' medoid (the sample whose tool point is nearest all the others
in sum; among the 20 nearest the middle, the first the robot has a path to from where it
starts), at that sample's flange orientation and IK branch; edge ``cube_edge`` (default:
80 % of the sample flange positions' smallest 10-90 % range, at most 0.25 m), shrunk by 0.75
until every model's five poses are reachable, collision-free, with collision-free paths
(straight, or the sampling run's detour), and inside the calibrated region
(``compensate.Region``: the samples' flange hull + 50 mm, their joint ranges + 2 deg). A
cube of the user's (``--cube-mm``) is not shrunk; how far it reaches outside is reported.
Each ISO point's distance to the nearest sample's tool point is reported
(``cube.nearest_sample_mm``). Its diagonal plane through corners (-,-,-), (+,+,-),
(+,+,+), (-,-,+) holds P1 (the centre) and P2..P5, on the diagonals at a tenth of the
diagonal from the corners. The twin drives there as the robot does (the sampling run's
step path, ``sampling.driver``; a joint's backlash follows the direction it came from)
and settles (a fresh repeatability draw). ``cycles`` (30) cycles P1 -> P5. Per pose:
  AP = |barycentre of the attained positions - commanded position|
  RP = l_bar + 3 S_l,  l_j = |x_j - barycentre|, S_l their sample std;
a set's AP is its worst pose's.

Two frames. ISO 9283 measures in the robot's base coordinate system: the measurement is
registered to the robot as it stands (``robot_frame``: the frame of joint 1 at its zero,
i.e. J1's axis, J1's zero direction and the height of that frame, which a laser tracker
finds from the robot's own first axis). AP is in that frame. The cell frame (``_cell``) is
the twin's world: what a program written in the nominal cell coordinates reaches; it adds
the robot's placement (the base frame error of a realistic world) and J1's zero offset
delta1, which no plane calibration can see (a turn about J1 or a shift of the whole robot
moves the plates with it).

Gauge block (9.3): a block of length L (default 100 mm) stands on the (true) plate at its
centre, its two measuring faces perpendicular to the plate and to the plate's x edge.
Four points on each face (a 20 x 20 mm square around the face centre, ``face_height``
above the plate) are measured by the laser with the beam pointing into the face, tilted
down towards the plate by ``tilt`` (sensor above the plate); the pose is chosen with the
validated model (the block where its calibrated plate is, its sensor pose, IK with its
offsets then Newton on its whole model; collision-free target in ``CollisionWorld``, which
does not know the block), as a user aims the laser after calibrating, and the twin
measures: the true sensor pose (MuJoCo site, with the
repeatability draw of that pose) and a ray to the analytic face plane, plus the laser
noise of a 100-reading mean and the laser's linearity error of the world (``twin.ticks``'s
laser model). Each model turns (counts, distance) into a point
``o_b + d z_b``; a plane is fitted to each face's four points; the length is the mean
distance of each face's points from the other face's plane (both ways, averaged); its
error against L is reported for the nominal model (scene nominal sensor pose, zero
offsets), the validated calibration, and its sensor pose with nominal offsets (to separate
the offsets' share). ``gauge_repeats`` repetitions give mean and std. The block is
modelled analytically, not as MuJoCo geometry. Where the block cannot be measured (no
pose reaches a face, no path, a reading out of the laser's range) the validation keeps its
ISO figures and says why beside them (``gauge_failed``).

Over truths (``validate_truth``, a pure function of a ``TruthJob``): draw the world
(``TruthJob.rehearsal().world``), sample a calibration set on that world's twin
(``twin_samples``: the sampling run's planner, collision checks and laser reads),
calibrate it from the nominal values (``estimation.calibrate.calibrate``, at each level),
validate on the same world. ``summarize`` gives median and worst per figure and per level;
``breakdown`` repeats one truth without the noise (the same poses rehearsed noise-free:
``noise_share``, and whether it dominates) and with each error family of
``twin.world.SOURCES`` on alone (or switched off in turn, the noise off too) and reports
the figures per variant: what each source leaves without the noise (``cannot_remove``,
with whether the level models it), the level's floor and what the oracle leaves there.
The truths and the variants run on ``studies.distributed.Engine`` (``run_jobs``).
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
                                                cannot_remove, levels_beside, noise_share,
                                                run_jobs,
                                                summarize, truth_row, truth_run,
                                                validate_truth)

__all__ = ["ANCHORS", "BREAKDOWN_KEYS", "CUBE_RULE", "FIGURE_KEYS", "FORMAT", "IsoPlan",
           "LEVEL_KEYS", "Mover", "OLD_FORMATS", "ROLES", "SamplePoses", "TRUTH_KEYS",
           "TruthJob", "ValidationSettings", "WHERE", "ap_rp", "breakdown",
           "breakdown_variants", "cannot_remove", "default_edge", "figure_keys", "figures",
           "gauge_block", "gauge_block_geometry", "gauge_length", "iso9283", "iso_points",
           "laser_reading_mm", "length_from", "levels_beside", "medoid", "medoid_order",
           "named_tcps",
           "nearest_sample_m", "noise_share", "plan_iso", "predicted_spread", "robot_frame", "run_jobs",
           "summarize", "truth_row", "truth_run", "validate", "validate_truth"]
