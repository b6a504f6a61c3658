"""planecal replay SAMPLES --params P.json [--scene S] [--errors ideal|realistic|FILE.json]
[--truth-seed T] [--out R.json]

Replays a recorded sample file's encoder counts in the twin (the cell = P): per sample the
measured distance, the twin's MuJoCo ray cast, the analytic model and what the ray hit;
summary mean, std and max |twin - measured| (predicted - measured, the one sign). The
cell is the run's (its sidecar) and P's (a result's provenance), else --scene, else
thesis_final; a --scene that contradicts them is refused. The twin's robot is the world
the run was made in, as its files say (``jobs.runs.run_world``):
P's own world when P is a truth file (rehearse --truth-out), else the world the sample
file's sidecar names (a rehearsal's error profile and truth seed); --errors and
--truth-seed choose it only where nothing is recorded (default realistic, seed 0), and
are refused where they contradict the record. In a world of a profile the joints carry
its errors at rest (compliance, gear error; no noise), so twin - analytic shows what the
errors the model lacks do to each distance; --errors ideal: the robot is the nominal model
exactly (twin = analytic to ~1e-9 mm).
Example: planecal replay examples/seed_samples.tsv --params examples/table10_params.json
"""
from __future__ import annotations

from planecal.commands.value_options import seed
from planecal.jobs.predict import REPLAY_FORMAT


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    p.add_argument("samples", help="sample file, seed format (7.1.4)")
    p.add_argument("--params", required=True, help="parameter file: the twin's truth")
    add_scene_argument(p, "the plates and robot", reads="the run's sidecar and --params' provenance")
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin robot's error profile where the files record none "
                        "(default realistic)")
    p.add_argument("--truth-seed", type=seed, default=None,
                   help="seed of the world's geometry and gear phases where the files record "
                        "none (default 0)")
    p.add_argument("--out", help="write the per-sample table and summary (JSON) here")


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.cell_options import run_scene_inputs
    from planecal.commands.io_options import Files, profile_inputs, with_sidecars
    f = Files().read(*with_sidecars([args.samples]), args.params,
                     *run_scene_inputs([args.samples], args.scene),
                     *profile_inputs(args.errors, args.scene))
    return f.write(args.out, "--out", REPLAY_FORMAT)


def run(args) -> int:
    from planecal.jobs.predict import ReplayRequest, replay
    replay(ReplayRequest(args.samples, args.params, args.scene, args.errors, args.truth_seed,
                         args.out))
    return 0
