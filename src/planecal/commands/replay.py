"""planecal replay SAMPLES --params P.json [--scene S] [--out R.json]

Replays a recorded sample file's encoder counts in the twin (truth = P, no error
sources): per sample the measured distance, the twin's MuJoCo ray cast, the analytic
model and what the ray hit; summary mean, std and max |measured - twin|.
Example: planecal replay examples/seed_samples.tsv --params examples/table10_params.json
"""
from __future__ import annotations


REPLAY_FORMAT = "planecal-replay/1"


def add_arguments(p):
    from planecal.scene import DEFAULT_SCENE
    p.add_argument("samples", help="sample file, seed format (7.1.4)")
    p.add_argument("--params", required=True, help="parameter file: the twin's truth")
    p.add_argument("--scene", default=DEFAULT_SCENE, help="scene (default %(default)s)")
    p.add_argument("--out", help="write the per-sample table and summary (JSON) here")


def run(args) -> int:
    from planecal.outputs import check_output
    from planecal.params import load_params, save_json
    from planecal.samples import read_samples
    from planecal.scene import load_scene
    from planecal.studies.replay import format_replay, replay

    if args.out:  # checked before any work (issue 16): never an input, never a directory
        check_output(args.out, [args.samples, args.params], REPLAY_FORMAT)
    s = read_samples(args.samples)
    params = load_params(args.params)
    scene = load_scene(args.scene)
    res = replay(scene, params, s.qe, s.d_mm, s.plate)
    res = {"format": REPLAY_FORMAT, **res}
    res["samples_file"] = str(args.samples)
    res["params_file"] = str(args.params)
    print(format_replay(res))
    if args.out:
        save_json(args.out, res)
        print(f"result written to {args.out}")
    return 0
