"""planecal urdf [--params RESULT.json] [--scene S] --out FILE.urdf [--no-meshes] [--force]
[--mesh-prefix PREFIX]

The robot as URDF: base link ``base``, six revolute joints whose values are planecal's
joint angles q, ``flange`` and the sensor frame ``laser`` (fixed children), robot.json's
masses as the links' inertials. Without --params: the nominal model (zero joint offsets,
the scene's nominal sensor pose); with --params (a calibration result or parameter file
made for the scene's robot, else refused; one whose verdict found it no better than a
simpler level is refused without --force): the calibrated model, its joint offsets,
joint geometry and base frame in the joint origins, and its sensor pose. What a URDF
cannot hold (joint compliance; level 3's gear harmonics, backlash and laser linearity)
is left out, said in one line on stderr. Visual and collision meshes (planecal.model.geometry's, as
the twin and the collision checker use them) go as STL files into FILE_meshes/ beside
the URDF, referenced by a relative path, or by PREFIX + file name (e.g.
package://mc70_description/meshes/). See planecal.io.urdf.
"""
from __future__ import annotations

import sys
from pathlib import Path



def add_arguments(p):
    from planecal.model.scene import DEFAULT_SCENE
    p.add_argument("--params", metavar="RESULT.json",
                   help="calibration result or parameter file (default: the nominal model)")
    p.add_argument("--scene", default=DEFAULT_SCENE,
                   help="scene for the robot and the nominal sensor pose (default %(default)s)")
    p.add_argument("--out", required=True, metavar="FILE.urdf", help="URDF file to write")
    p.add_argument("--no-meshes", action="store_true",
                   help="write the kinematic tree only (no visual or collision shapes)")
    p.add_argument("--force", action="store_true",
                   help="write a result whose verdict found it no better than a simpler level "
                        "(estimation.verdict), and replace --out even if planecal did not "
                        "write it")
    p.add_argument("--mesh-prefix", default=None, metavar="PREFIX",
                   help="mesh file names in the URDF are PREFIX + name (default: the relative "
                        "path FILE_meshes/name)")


def _mesh_dir(out) -> Path:
    out = Path(out)
    return out.with_name(out.stem + "_meshes")


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the URDF and
    its mesh folder."""
    from planecal.commands.io_options import Files, scene_inputs
    from planecal.io.outputs import STL_MARK, URDF_MARK
    f = Files().read(args.params, role="--params").read(*scene_inputs(args.scene))
    f.write(args.out, "--out", URDF_MARK)
    if not args.no_meshes:
        f.write(_mesh_dir(args.out), "--out's mesh folder", folder=True,
                members=(("*.stl", (STL_MARK,)),))
    return f


def write_meshes(scene, params, mesh_dir: Path, prefix: str):
    """STL files of the link and tool shapes (planecal.model.geometry) and their MeshRefs;
    each STL's header says planecal wrote it (``outputs.STL_MARK``)."""
    from trimesh.exchange.stl import export_stl

    from planecal.io.outputs import STL_MARK, make_folder
    from planecal.model.geometry import robot_link_meshes, tool_meshes
    from planecal.io.urdf import MeshRef
    make_folder(mesh_dir, "--out's mesh folder")
    refs = []
    for kind in ("visual", "collision"):
        for lm in robot_link_meshes(scene.robot, kind) + tool_meshes(scene, kind, sensor=params):
            mesh = lm.mesh.transformed(lm.T_body_mesh).to_trimesh()
            fname = f"{lm.name}_{kind}.stl"
            data = export_stl(mesh)
            (mesh_dir / fname).write_bytes(STL_MARK.ljust(80, b" ") + data[80:])
            refs.append(MeshRef(lm.body, kind, prefix + fname, name=f"{lm.name}_{kind}"))
    return refs


def run(args) -> int:
    from planecal.io.params import load_params
    from planecal.model.scene import load_scene, nominal_params
    from planecal.io.urdf import not_in_urdf, urdf_text

    scene = load_scene(args.scene)
    out = Path(args.out)  # checked before the run (``files``)
    if args.params:
        from planecal.commands.controller_options import refuse_worse
        from planecal.formats.base import read_json
        refuse_worse(read_json(args.params, "calibration result"), args.params, args.force)
        params = load_params(args.params, scene.robot)
        source = f"calibrated: {args.params}"
    else:
        params = nominal_params(scene)
        source = f"nominal: scene {scene.name}"
    text = urdf_text(scene.robot, params, meshes=[], source=source)  # a bad model: nothing written
    refs = []
    if not args.no_meshes:
        mesh_dir = _mesh_dir(out)
        prefix = args.mesh_prefix if args.mesh_prefix is not None else mesh_dir.name + "/"
        refs = write_meshes(scene, params, mesh_dir, prefix)
        text = urdf_text(scene.robot, params, meshes=refs, source=source)
    out.write_text(text, encoding="utf-8")
    left = not_in_urdf(params)
    if left:
        print(f"note: {args.params} also corrects {', '.join(left)}: a URDF is a fixed chain "
              f"and cannot hold {'it' if len(left) == 1 else 'them'}, so {out} does not "
              "(planecal compensate corrects a program's targets with the joints' errors)",
              file=sys.stderr)
    print(f"URDF written to {out} ({source}"
          + (f"; {len(refs)} meshes in {out.stem}_meshes/" if refs else "") + ")")
    return 0
