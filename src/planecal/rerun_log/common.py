"""Recording files, streams, colours and the static cell/robot geometry shared by the
sampling and fit recordings. The entity tree is documented in docs/RERUN.md."""
from __future__ import annotations

import os
import uuid
from datetime import datetime
from pathlib import Path

import numpy as np

from planecal.errors import InputError

APP_ID = "planecal"
DEFAULT_DIR = "recordings"  # relative to the working directory (see recordings/README.md)
AUTO_NAMES = ("", "auto", "-")  # --rrd values that mean "a generated name in recordings/"
RRD_MAGIC = b"RRF"  # "RRF2" in rerun 0.41; older files start "RRF0"/"RRF1"

# colours (RGBA)
PLATE_RGBA = (150, 170, 200, 255)
STAND_RGBA = (120, 120, 120, 255)
FLOOR_RGBA = (70, 70, 70, 255)
OBSTACLE_RGBA = (230, 140, 40, 140)
LINK_RGBA = (235, 160, 20, 255)  # NACHI orange
BASE_RGBA = (90, 90, 90, 255)
TOOL_RGBA = (60, 60, 70, 255)
BEAM_RGBA = (255, 30, 30, 255)
BEAM_NONE_RGBA = (160, 160, 160, 180)  # no reading (out of range / no hit)
HIT_RGBA = (255, 230, 0, 255)
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


def is_recording(path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(len(RRD_MAGIC)) == RRD_MAGIC
    except OSError:
        return False


def eye_controls(scene, kind: str = "cell"):
    """A starting camera for the 3D view: ``"cell"`` looks at the robot and the first
    plate from the side; ``"plate"`` looks at the first plate's measured face."""
    import rerun.blueprint as rrb

    if scene is None or not scene.plates:
        return None
    from planecal.cell import point_normal_from_n_tilde

    plate = scene.plates[0]
    c = plate.center()
    if kind == "plate":
        _, nhat = point_normal_from_n_tilde(plate.n_tilde)
        pos = c + plate.face * nhat * 1.2 + np.array([0.0, 0.0, 0.4])
        return rrb.EyeControls3D(position=pos, look_target=c, eye_up=[0, 0, 1])
    target = 0.5 * (c + np.array([0.0, 0.0, 0.8]))
    d = np.array([c[0], c[1], 0.0])
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-6 else np.array([1.0, 0, 0])
    side = np.array([-d[1], d[0], 0.0])
    pos = target + 2.8 * side - 0.8 * d + np.array([0.0, 0.0, 1.4])
    return rrb.EyeControls3D(position=pos, look_target=target, eye_up=[0, 0, 1])


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


# ----- static geometry -----

def _mesh3d(rr, mesh, color, T=None):
    V = np.asarray(mesh.vertices, float)
    if T is not None and not np.allclose(T, np.eye(4)):
        V = V @ T[:3, :3].T + T[:3, 3]
    return rr.Mesh3D(vertex_positions=V, triangle_indices=np.asarray(mesh.faces, np.uint32),
                     vertex_normals=np.asarray(mesh.vertex_normals, float), albedo_factor=color)


def log_cell(rec, scene, planes_n_tilde=None) -> list[str]:
    """Static meshes of the cell (``planecal.geometry.scene_meshes``, the twin's and the
    collision checker's shapes): /cell/plates/<name>, /cell/stands/<name>, /cell/floor,
    /cell/obstacles/<name>. Returns the entity paths."""
    from planecal.geometry import scene_meshes

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
    (frame 6), visual shapes of ``planecal.geometry``. The frames' poses are
    Transform3D on /robot/link_<i> and /robot/tool; link_0 (the base) is static."""
    from planecal.geometry import robot_link_meshes, tool_meshes

    rr = _rr()
    for lm in robot_link_meshes(scene.robot, "visual"):
        color = BASE_RGBA if lm.body == 0 else LINK_RGBA
        rec.log(f"/robot/link_{lm.body}/{lm.name}", _mesh3d(rr, lm.mesh, color, lm.T_body_mesh),
                static=True)
    for lm in tool_meshes(scene, "visual", sensor=sensor_params):
        rec.log(f"/robot/tool/{lm.name}", _mesh3d(rr, lm.mesh, TOOL_RGBA, lm.T_body_mesh),
                static=True)
    rec.log("/robot/link_0", rr.Transform3D(translation=[0, 0, 0], mat3x3=np.eye(3)), static=True)


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
