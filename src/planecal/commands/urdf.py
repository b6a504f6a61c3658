"""planecal urdf [--params RESULT.json] [--scene S] --out FILE.urdf [--no-meshes]
[--mesh-prefix PREFIX] [--force]

The robot as URDF: base link ``base``, six revolute joints whose values are planecal's
joint angles q, ``flange`` and the sensor frame ``laser`` (fixed children), robot.json's
masses as the links' inertials. Without --params: the nominal model (zero joint offsets,
the scene's nominal sensor pose); with --params (a calibration result, in the scene its
provenance records: a --scene that contradicts it is refused; or a parameter file, made
for the scene's robot, else refused; a result that is not a calibration -- its fit did
not converge or could not identify a free parameter -- is refused, nothing written,
unless --force): the calibrated model, its joint offsets,
joint geometry and base frame in the joint origins, and its sensor pose. What a URDF
cannot hold (joint compliance; level 3's gear harmonics, backlash and laser linearity)
is left out, said in one line on stderr. Visual and collision meshes (planecal.model.geometry's, as
the twin and the collision checker use them) go as STL files into FILE_meshes/ beside
the URDF, referenced by a relative path, or by PREFIX + file name (e.g.
package://mc70_description/meshes/). See planecal.io.urdf.
"""
from __future__ import annotations


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    p.add_argument("--params", metavar="RESULT.json",
                   help="calibration result or parameter file (default: the nominal model)")
    add_scene_argument(p, "the robot and the nominal sensor pose", reads="--params' provenance")
    p.add_argument("--out", required=True, metavar="FILE.urdf", help="URDF file to write")
    p.add_argument("--no-meshes", action="store_true",
                   help="write the kinematic tree only (no visual or collision shapes)")
    p.add_argument("--mesh-prefix", default=None, metavar="PREFIX",
                   help="mesh file names in the URDF are PREFIX + name (default: the relative "
                        "path FILE_meshes/name)")
    p.add_argument("--force", action="store_true",
                   help="write --out over a file planecal did not write, and a URDF of a "
                        "result that is not a calibration (said on stderr)")


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the URDF and
    its mesh folder."""
    from planecal.commands.cell_options import result_scene_inputs
    from planecal.commands.io_options import Files, scene_inputs
    from planecal.io.outputs import STL_MARK, URDF_MARK
    from planecal.jobs.exports import mesh_dir
    f = Files().read(args.params, role="--params").read(
        *(result_scene_inputs(args.params, args.scene) if args.params
          else scene_inputs(args.scene)))
    f.write(args.out, "--out", URDF_MARK)
    if not args.no_meshes:
        f.write(mesh_dir(args.out), "--out's mesh folder", folder=True,
                members=(("*.stl", (STL_MARK,)),))
    return f


def run(args) -> int:
    from planecal.jobs.exports import UrdfRequest, urdf
    urdf(UrdfRequest(args.out, args.params, args.scene, not args.no_meshes, args.mesh_prefix,
                     args.force))
    return 0
