"""Recording files, streams, colours and the static cell/robot geometry shared by the
sampling and fit recordings. The entity tree is documented in docs/RERUN.md."""
from __future__ import annotations

import os
import uuid
from datetime import datetime
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.io.outputs import RRD_MAGIC

APP_ID = "planecal"
DEFAULT_DIR = "recordings"  # relative to the working directory (see recordings/README.md)
AUTO_NAMES = ("", "auto", "-")  # --rrd values that mean "a generated name in recordings/"

# recording kinds: each has a blueprint of its own (docs/RERUN.md)
KINDS = ("rehearsal", "real", "calibration", "montecarlo", "bootstrap", "validate", "compare")

# colours (RGBA). The beam is green: no sample colour scale and no rejection uses green.
PLATE_RGBA = (95, 105, 125, 255)  # dark slate: light, blue and red samples all show on it
STAND_RGBA = (120, 120, 120, 255)
FLOOR_RGBA = (70, 70, 70, 255)
OBSTACLE_RGBA = (230, 140, 40, 140)
LINK_RGBA = (235, 160, 20, 255)  # NACHI orange
BASE_RGBA = (90, 90, 90, 255)
TOOL_RGBA = (60, 60, 70, 255)
BEAM_RGBA = (40, 230, 60, 255)
BEAM_NONE_RGBA = (160, 160, 160, 180)  # no reading (out of range / no hit)
HIT_RGBA = (150, 255, 160, 255)  # the beam's end, a lighter green
BEAM_RADIUS_M = 0.003
HIT_RADIUS_M = 0.004
REJECT_RGBA = {"collision": (220, 40, 40, 255), "laser": (240, 160, 0, 255),
               "unreachable": (150, 60, 200, 255)}


def _rr():
    try:
        import rerun as rr
    except ModuleNotFoundError as e:  # pragma: no cover - rerun-sdk is a dependency
        raise InputError(f"--rrd: Rerun logging needs rerun-sdk (missing module {e.name})") \
            from None
    return rr


def recording_path(arg, command: str, scene_name: str, now: datetime | None = None) -> Path:
    """Where a recording goes. ``arg`` None, "", "auto" or "-": a generated name in
    ``recordings/``; an existing directory, or a path ending in "/": a generated name
    there (created if missing); else the file itself (".rrd" appended when it has no
    suffix; its directory must exist). Generated names are
    ``<command>-<scene>-<YYYYmmdd-HHMMSS>.rrd`` (local time; "-2", "-3", ... if taken)."""
    def generated(folder: Path) -> Path:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(f"--rrd {folder}: cannot create the directory "
                             f"({e.strerror})") from None
        stamp = (now or datetime.now()).strftime("%Y%m%d-%H%M%S")
        safe = "".join(c if c.isalnum() or c in "._-" else "_" for c in str(scene_name)) or "scene"
        base = f"{command}-{safe}-{stamp}"
        p = folder / f"{base}.rrd"
        k = 2
        while p.exists():
            p = folder / f"{base}-{k}.rrd"
            k += 1
        return p

    if arg is None or str(arg).strip() in AUTO_NAMES:
        return generated(Path(DEFAULT_DIR))
    s = str(arg)
    p = Path(s).expanduser()
    if p.is_dir() or s.endswith(("/", os.sep)):
        if p.exists() and not p.is_dir():
            raise InputError(f"--rrd {s}: not a directory")
        return generated(p)
    if not p.suffix:
        p = p.with_suffix(".rrd")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"--rrd {s}: directory {parent} does not exist")
    if p.exists() and not os.access(p, os.W_OK):
        raise InputError(f"--rrd {s}: not writable")
    return p


def open_recording(path: Path, blueprint=None, name: str | None = None):
    """A RecordingStream saving to ``path`` (headless; no viewer is spawned), with the
    default blueprint embedded. No wall-clock "log_time" timeline: only the planecal
    timelines (tick, robot_time / iteration)."""
    rr = _rr()
    rec = rr.RecordingStream(APP_ID, recording_id=str(uuid.uuid4()))
    rec.set_log_time_enabled(False)
    try:
        rec.save(str(path), default_blueprint=blueprint)
    except Exception as e:  # rerun raises its own error types for unwritable paths
        raise InputError(f"--rrd {path}: cannot write the recording ({e})") from None
    if name:
        rec.send_recording_name(name)
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    return rec


def close_recording(rec) -> None:
    """Flush everything to the file and finish it (the footer is written)."""
    rec.flush()
    rec.disconnect()


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3), vectorised
    (Shepperd: from the largest of |w|, |x|, |y|, |z|, so 180-degree turns are exact)."""
    m = R.reshape(-1, 3, 3)
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    d21, d02, d10 = m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]
    s01, s02, s12 = m[:, 0, 1] + m[:, 1, 0], m[:, 0, 2] + m[:, 2, 0], m[:, 1, 2] + m[:, 2, 1]
    cand = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22,
                     1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    k = np.argmax(cand, -1)
    big = 0.5 * np.sqrt(np.maximum(cand[np.arange(len(m)), k], 1e-300))
    f = 0.25 / big
    q = np.empty((len(m), 4))
    for case, (x, y, z, w) in enumerate((
            (d21 * f, d02 * f, d10 * f, big),   # w largest
            (big, s01 * f, s02 * f, d21 * f),   # x largest
            (s01 * f, big, s12 * f, d02 * f),   # y largest
            (s02 * f, s12 * f, big, d10 * f))):  # z largest
        sel = k == case
        q[sel] = np.stack([x, y, z, w], -1)[sel]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q.reshape(R.shape[:-2] + (4,))


def is_recording(path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(len(RRD_MAGIC)) == RRD_MAGIC
    except OSError:
        return False


def plate_face_normal(scene, plate: int = 0, planes_n_tilde=None) -> np.ndarray:
    """Unit normal of a plate's measured face, pointing to the sensor's side."""
    pl = scene.plates[plate]
    n = None if planes_n_tilde is None else np.asarray(planes_n_tilde, float)[plate]
    return pl.frame(n)[:3, 2]


def eye_controls(scene, tool=None, distance_m: float = 0.8, arm=None):
    """A starting camera for the 3D view that frames the first plate and the tool: it looks
    at the midpoint of the plate's centre and ``tool`` (a point, m; default: 0.15 m in front
    of the plate's face, where the sensor works) from ``distance_m`` away, from in front of
    the measured face and from the side of the robot's reach (the arm, which lies near
    the vertical plane through the base and the tool, is seen side-on and does not hide
    the plate): the side away from ``arm`` (a point, e.g. the elbow of the pose shown),
    or without it the side the face looks to."""
    import rerun.blueprint as rrb

    if scene is None or not scene.plates:
        return None
    c = scene.plates[0].center()
    n = plate_face_normal(scene)
    tool = c + 0.15 * n if tool is None else np.asarray(tool, float)
    target = 0.5 * (c + tool)
    out = np.array([c[0], c[1], 0.0])
    out = out / np.linalg.norm(out) if np.linalg.norm(out) > 1e-6 else np.array([1.0, 0, 0])
    side = np.cross([0.0, 0.0, 1.0], out)
    if arm is not None:
        if side @ (np.asarray(arm, float) - target) > 0:
            side = -side
    elif side @ n < 0:  # the side the face looks to
        side = -side
    d = 0.65 * n + 0.7 * side + 0.15 * out
    pos = target + distance_m * d / np.linalg.norm(d)
    return rrb.EyeControls3D(position=pos, look_target=target, eye_up=[0, 0, 1])


def hidden(*paths):
    """View overrides that hide these entity subtrees when the recording opens (the
    user ticks them on in the blueprint panel)."""
    import rerun.blueprint as rrb

    return {p: rrb.EntityBehavior(visible=False) for p in paths}


def whole_range(timeline: str):
    """A visible time range covering the whole timeline (for an overview plot)."""
    import rerun.blueprint as rrb

    return rrb.VisibleTimeRange(timeline, start=rrb.TimeRangeBoundary.infinite(),
                                end=rrb.TimeRangeBoundary.infinite())


def whole_axis():
    """A time axis showing the whole timeline (not a window around the time cursor)."""
    import rerun.blueprint as rrb

    return rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                 end=rrb.TimeRangeBoundary.infinite()))


# ----- colours -----

def diverging_colors(values: np.ndarray, scale: float | None = None) -> np.ndarray:
    """RGB uint8 (N,3) on a blue-white-red scale over [-scale, +scale] (default: the
    largest magnitude): negative blue, zero light grey, positive red."""
    v = np.asarray(values, float)
    if scale is None:
        scale = float(np.max(np.abs(v))) if v.size else 1.0
    t = np.clip(v / scale, -1.0, 1.0) if scale > 0 else np.zeros_like(v)
    blue, mid, red = np.array([59, 76, 192.]), np.array([221, 221, 221.]), np.array([180, 4, 38.])
    a = np.abs(t)[:, None]
    rgb = np.where(t[:, None] < 0, mid + a * (blue - mid), mid + a * (red - mid))
    return np.rint(rgb).astype(np.uint8)


# sequential scale for "order" colours: dark blue -> purple -> orange -> yellow (no green:
# the beam is green)
SEQ_STOPS = np.array([[40, 30, 140], [150, 40, 160], [240, 120, 60], [250, 230, 40]], float)


def sequential_colors(values: np.ndarray, lo: float | None = None,
                      hi: float | None = None) -> np.ndarray:
    """RGB uint8 (N,3) on the dark blue -> purple -> orange -> yellow scale over
    [lo, hi] (default: min and max of ``values``)."""
    v = np.asarray(values, float)
    if not v.size:
        return np.zeros((0, 3), np.uint8)
    lo = float(np.min(v)) if lo is None else lo
    hi = float(np.max(v)) if hi is None else hi
    t = np.clip((v - lo) / (hi - lo), 0, 1) if hi > lo else np.zeros_like(v)
    x = np.linspace(0, 1, len(SEQ_STOPS))
    rgb = np.stack([np.interp(t, x, SEQ_STOPS[:, k]) for k in range(3)], -1)
    return np.rint(rgb).astype(np.uint8)


def lifted(points: np.ndarray, normals: np.ndarray, radius: float) -> np.ndarray:
    """Where a sample sphere of ``radius`` is drawn: its centre one radius off the face
    along the face normal, so it sits on the plate instead of half inside it (the hit
    point is where the sphere touches the face; the exact points are in the entity's
    data)."""
    return np.asarray(points, float) + radius * np.asarray(normals, float)


# ----- static geometry -----

def _mesh3d(rr, mesh, color, T=None):
    V = np.asarray(mesh.vertices, float)
    if T is not None and not np.allclose(T, np.eye(4)):
        V = V @ T[:3, :3].T + T[:3, 3]
    return rr.Mesh3D(vertex_positions=V, triangle_indices=np.asarray(mesh.faces, np.uint32),
                     vertex_normals=np.asarray(mesh.vertex_normals, float), albedo_factor=color)


def log_cell(rec, scene, planes_n_tilde=None) -> list[str]:
    """Static meshes of the cell (``planecal.model.geometry.scene_meshes``, the twin's and the
    collision checker's shapes): /cell/plates/<name>, /cell/stands/<name>, /cell/floor,
    /cell/obstacles/<name>. Returns the entity paths."""
    from planecal.model.geometry import scene_meshes

    rr = _rr()
    paths = []
    colors = {"plate": PLATE_RGBA, "stand": STAND_RGBA, "floor": FLOOR_RGBA,
              "obstacle": OBSTACLE_RGBA}
    for sm in scene_meshes(scene, planes_n_tilde):
        name = rr.escape_entity_path_part(sm.name)
        path = {"plate": f"/cell/plates/{name}", "stand": f"/cell/stands/{name}",
                "floor": "/cell/floor", "obstacle": f"/cell/obstacles/{name}"}[sm.kind]
        rec.log(path, _mesh3d(rr, sm.mesh, colors[sm.kind]), static=True)
        paths.append(path)
    return paths


def log_robot_meshes(rec, scene, sensor_params=None) -> None:
    """Static link meshes under /robot/link_<i>/<piece> (i = DH frame 0..6, vertices in
    that frame) and the tool (flange adapter, laser head) under /robot/tool/<piece>
    (frame 6), visual shapes of ``planecal.model.geometry``. The frames' poses are
    Transform3D on /robot/link_<i> and /robot/tool; link_0 (the base) is static."""
    from planecal.model.geometry import robot_link_meshes, tool_meshes

    rr = _rr()
    for lm in robot_link_meshes(scene.robot, "visual"):
        color = BASE_RGBA if lm.body == 0 else LINK_RGBA
        rec.log(f"/robot/link_{lm.body}/{lm.name}", _mesh3d(rr, lm.mesh, color, lm.T_body_mesh),
                static=True)
    for lm in tool_meshes(scene, "visual", sensor=sensor_params):
        rec.log(f"/robot/tool/{lm.name}", _mesh3d(rr, lm.mesh, TOOL_RGBA, lm.T_body_mesh),
                static=True)
    rec.log("/robot/link_0", rr.Transform3D(translation=[0, 0, 0], mat3x3=np.eye(3)), static=True)


def hit_columns(points) -> dict:
    """The exact hit points as AnyValues columns (x, y, z in m; AnyValues takes 1-D
    arrays only)."""
    p = np.asarray(points, float).reshape(-1, 3)
    return {"hit_x_m": p[:, 0], "hit_y_m": p[:, 1], "hit_z_m": p[:, 2]}


def log_robot_pose(rec, scene, params, qe, d_m=None, *, with_meshes: bool = True):
    """The robot (links and tool) posed at encoder counts ``qe`` (6,) with ``params``
    (joint offsets, sensor pose), static, and the beam from the sensor along its
    direction to the hit ``d_m`` metres away (grey to the end of the laser window when
    ``d_m`` is None or NaN). For recordings without a run (fit, studies): the pose of one
    sample. Entity paths as in a sampling recording."""
    from planecal.model.measurement import beam_direction
    from planecal.model.encoder import counts_to_joints
    from planecal.model.kinematics import link_frames

    rr = _rr()
    if with_meshes:
        log_robot_meshes(rec, scene, params)
    q = counts_to_joints(scene.robot, np.asarray(qe, np.int64).reshape(1, -1))
    F = link_frames(scene.robot.kinematics.with_offsets(params.joint_offsets), q)[0]
    for b in range(1, F.shape[0]):
        rec.log(f"/robot/link_{b}", rr.Transform3D(translation=F[b, :3, 3],
                                                   mat3x3=F[b, :3, :3]), static=True)
    F6 = F[-1]
    rec.log("/robot/tool", rr.Transform3D(translation=F6[:3, 3], mat3x3=F6[:3, :3]),
            static=True)
    o_b = F6[:3, :3] @ params.sensor_origin + F6[:3, 3]
    z_b = F6[:3, :3] @ beam_direction(params.phi_y, params.phi_z)
    has = d_m is not None and np.isfinite(d_m)
    d = float(d_m) if has else float(scene.laser_range_mm[1]) * 1e-3
    rec.log("/laser/beam", rr.Arrows3D(origins=[o_b], vectors=[z_b * d],
                                       colors=[BEAM_RGBA if has else BEAM_NONE_RGBA],
                                       radii=BEAM_RADIUS_M), static=True)
    if has:
        rec.log("/laser/hit", rr.Points3D([o_b + d * z_b], colors=[HIT_RGBA],
                                          radii=HIT_RADIUS_M), static=True)
    return o_b


SAMPLE_RADIUS_M = 0.004


def sample_points(scene, params, qe, d_m, plate):
    """Hit points (N,3) of samples with ``params`` and the face normals of their plates
    (on ``params``' planes when it has one per plate of the scene)."""
    from planecal.model.measurement import sensor_in_base
    from planecal.model.encoder import counts_to_joints

    qe = np.asarray(qe, np.int64).reshape(-1, 6)
    o_b, z_b = sensor_in_base(scene.robot, counts_to_joints(scene.robot, qe), params)
    p = o_b + np.asarray(d_m, float)[:, None] * z_b
    planes = params.planes if params.n_planes == len(scene.plates) else None
    n = np.array([plate_face_normal(scene, min(int(k), len(scene.plates) - 1), planes)
                  for k in np.asarray(plate, int)]).reshape(-1, 3)
    return p, n


def log_pose_set(rec, scene, params, qe, d_m, plate, colors, *, shown: int = 0,
                 extra=None) -> np.ndarray:
    """The 3D part of a recording without a run (calibration, studies): the cell on
    ``params``' planes, the robot at sample ``shown`` with its beam, and the samples'
    hit points as spheres on the plate faces in ``colors`` (static). ``extra``: more
    AnyValues columns for /samples/points. Returns the sensor origin of the pose shown
    (for the camera)."""
    rr = _rr()
    planes = params.planes if params.n_planes == len(scene.plates) else None
    log_cell(rec, scene, planes)
    d_m = np.asarray(d_m, float)
    plate = np.asarray(plate, int)
    p, n = sample_points(scene, params, qe, d_m, plate)
    tool = log_robot_pose(rec, scene, params, np.asarray(qe)[shown], d_m[shown])
    rec.log("/samples/points",
            rr.Points3D(lifted(p, n, SAMPLE_RADIUS_M), colors=colors, radii=SAMPLE_RADIUS_M),
            rr.AnyValues(plate=plate, **hit_columns(p), **(extra or {})), static=True)
    return tool


def tool_point(scene, params, qe) -> np.ndarray:
    """The sensor origin at encoder counts ``qe`` (6,) with ``params`` (the camera's
    second target)."""
    from planecal.model.measurement import sensor_in_base
    from planecal.model.encoder import counts_to_joints

    q = counts_to_joints(scene.robot, np.asarray(qe, np.int64).reshape(1, 6))
    return sensor_in_base(scene.robot, q, params)[0][0]


def pose_eye(scene, params, qe):
    """The starting camera for a recording that shows the robot at counts ``qe``: on the
    plate and the tool, from the side away from the arm (frames 2..4)."""
    from planecal.model.encoder import counts_to_joints
    from planecal.model.kinematics import link_frames

    q = counts_to_joints(scene.robot, np.asarray(qe, np.int64).reshape(1, 6))
    F = link_frames(scene.robot.kinematics.with_offsets(params.joint_offsets), q)[0]
    return eye_controls(scene, tool_point(scene, params, qe), arm=F[2:5, :3, 3].mean(0))


def log_info(rec, path: str, markdown: str) -> None:
    """A static markdown TextDocument (the run's info panel, legends)."""
    rr = _rr()
    rec.log(path, rr.TextDocument(markdown, media_type="text/markdown"), static=True)


def error_legend(scale_mm: float, what: str) -> str:
    """The markdown legend of the blue-grey-red model-error colours."""
    return (f"**sample colour** = {what}: blue = {-scale_mm:+.4g} mm or less, light grey = 0, "
            f"red = {scale_mm:+.4g} mm or more (linear in between)")


def blueprint_views(path) -> list[dict]:
    """The views of the blueprint stored in a recording file, read back with rerun's own
    reader (``rerun.chunk.RrdReader``): [{"class": "3D", "name", "origin", "contents":
    [queries], "hidden": [entity paths that start hidden], "eye": {"position",
    "look_target"} or None}]. For tests and ``planecal view --summary``."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    views: dict[str, dict] = {}

    def view(vid):
        return views.setdefault(vid, {"class": None, "name": None, "origin": None,
                                      "contents": [], "hidden": [], "eye": None})

    for entry in reader.blueprints():
        for ch in reader.store(store=entry).stream():
            parts = ch.entity_path.strip("/").split("/")
            if len(parts) < 2 or parts[0] != "view":
                continue
            rb = ch.to_record_batch()
            vals = {n: rb.column(n).to_pylist()[-1] for n in rb.schema.names
                    if n not in ch.timeline_names and "RowId" not in n}
            v = view(parts[1])
            if len(parts) == 2:
                for key, col in (("class", "class_identifier"), ("name", "display_name"),
                                 ("origin", "space_origin")):
                    x = vals.get(f"ViewBlueprint:{col}")
                    if x:
                        v[key] = x[0]
            elif parts[2:] == ["EyeControls3D"] and vals.get("EyeControls3D:position"):
                v["eye"] = {"position": np.array(vals["EyeControls3D:position"][0]),
                            "look_target": np.array(vals["EyeControls3D:look_target"][0])}
            elif parts[2:] == ["ViewContents"] and vals.get("ViewContents:query"):
                v["contents"] = list(vals["ViewContents:query"])
            elif parts[2:4] == ["ViewContents", "overrides"] and \
                    vals.get("EntityBehavior:visible") == [False]:
                ent = "/" + "/".join(parts[4:-1] if parts[-1] == "visualizers" else parts[4:])
                v["hidden"].append(ent)
    return [v for v in views.values() if v["class"]]


def summarize(path) -> list[tuple[str, int, bool, list[str]]]:
    """(entity path, rows, static, components) for each entity of a recording, sorted;
    read with rerun's own reader (``rerun.chunk.RrdReader``)."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for ch in RrdReader(str(path)).store().stream():
        e = ch.entity_path
        if e.startswith("/__"):
            continue
        rb = ch.to_record_batch()
        comps = [n for n in rb.schema.names
                 if n != "rerun.controls.RowId" and n not in ch.timeline_names]
        row = out.setdefault(e, [0, ch.is_static, set()])
        row[0] += ch.num_rows
        row[2].update(comps)
    return [(e, r[0], r[1], sorted(r[2])) for e, r in sorted(out.items())]
