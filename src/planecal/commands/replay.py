"""planecal replay SAMPLES --params P.json [--scene S] [--errors ideal|realistic|FILE.json]
[--truth-seed T] [--out R.json]

Replays a recorded sample file's encoder counts in the twin (the cell = P): per sample the
measured distance, the twin's MuJoCo ray cast, the analytic model and what the ray hit;
summary mean, std and max |twin - measured| (predicted - measured, the one sign). The
twin's robot is the world the run was made in, as its files say (twin.world.recorded_world):
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


REPLAY_FORMAT = "planecal-replay/1"


def add_arguments(p):
    from planecal.base.paths import DEFAULT_SCENE
    p.add_argument("samples", help="sample file, seed format (7.1.4)")
    p.add_argument("--params", required=True, help="parameter file: the twin's truth")
    p.add_argument("--scene", default=DEFAULT_SCENE, help="scene (default %(default)s)")
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin robot's error profile where the files record none "
                        "(default realistic)")
    p.add_argument("--truth-seed", type=seed, default=None,
                   help="seed of the world's geometry and gear phases where the files record "
                        "none (default 0)")
    p.add_argument("--out", help="write the per-sample table and summary (JSON) here")


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import Files, profile_inputs, scene_inputs, with_sidecars
    f = Files().read(*with_sidecars([args.samples]), args.params, *scene_inputs(args.scene),
                     *profile_inputs(args.errors, args.scene))
    return f.write(args.out, "--out", REPLAY_FORMAT)


def run(args) -> int:
    from planecal.io.params import load_json, load_params, save_json
    from planecal.twin.world import recorded_world
    from planecal.io.samples import read_samples
    from planecal.model.scene import load_scene
    from planecal.twin.world import sources_on
    from planecal.present.replay import format_replay
    from planecal.studies.replay import replay, replay_world
    from planecal.twin.profile import load_profile

    scene = load_scene(args.scene)
    s = read_samples(args.samples, scene)  # calibrate's check: the laser window, the plates
    params = load_params(args.params, scene.robot)
    doc = load_json(args.params, "parameter file")
    truth_file = args.params if isinstance(doc, dict) and doc.get("world") else None
    ref = recorded_world(scene, args.samples, truth_file, args.errors, args.truth_seed)
    profile = load_profile(ref.errors, scene.robot)
    world = opts = None
    if profile.name != "ideal" or truth_file is not None:
        world, opts = replay_world(scene, params, ref)
    res = {"format": REPLAY_FORMAT, **replay(scene, params, s.qe, s.d_mm, s.plate, world, opts)}
    res["samples_file"] = str(args.samples)
    res["params_file"] = str(args.params)
    res["errors"] = profile.name
    res["profile"] = str(profile.path)
    res["truth_seed"] = None if world is None else ref.truth_seed
    res["world"] = ref.to_dict()
    if world is None:
        print(f"twin: the ideal world (the nominal model exactly, truth = {args.params})")
    else:
        on = [f for f in sources_on(scene.robot, world, opts)]
        print(f"twin: {ref.describe()} with the cell of {args.params} (errors at rest: "
              f"{', '.join(on) or 'none'}; no noise)")
    print(format_replay(res))
    if args.out:
        save_json(args.out, res)
        print(f"result written to {args.out}")
    return 0
