"""Property tests (hypothesis): every reader of a planecal file, fed random bytes, random
JSON or a near-valid document (a valid one with one field mutated), either returns a
result that is physically usable or raises InputError with one line naming the file; never
any other exception.

Determinism: ``derandomize=True`` (examples derived from the test's source, the same on
every run and machine) and no example database, so CI cannot flake. ``deadline=None``:
the machine is shared, timing is no property of a reader.

Budget (max_examples): the readers share their first stage (bounded read, JSON parse,
top-level type), so random bytes and random JSON mostly hit the same few outcomes early;
40 examples per reader and strategy find those. Near-valid documents are where the checks
differ: each format has 30-110 field paths, times 14 mutations; 150 examples per format
put some mutation on most fields and each mutation on many fields (the unit tests in
test_schemas.py pin every check exactly). All 29 tests take ~5 s on an idle machine.
"""
import atexit
import copy
import json
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from planecal.base.errors import InputError
from planecal.formats import (
    ERRORS_FORMAT, MODELS, PARAMS_FORMAT, POSES_FORMAT, RESULT_FORMAT, ROBOT_FORMAT,
    SCENE_FORMAT, SHAPES_FORMAT, SIDECAR_FORMAT, load_sidecar)
from planecal.formats.params import provenance, result_document
from planecal.io.params import load_params
from planecal.base.paths import data_path
from planecal.model.kinematics import fk
from planecal.model.robot import load_robot
from repo import repo_path
from planecal.io.samples import read_samples
from planecal.model.scene import load_scene
from planecal.studies.planning import load_poses
from test_schemas import POSES, SIDECAR

# an overflow or invalid-value warning is a silently wrong number in the making: fail on it
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

SETTINGS = dict(derandomize=True, database=None, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])
FEW = settings(max_examples=40, **SETTINGS)
MANY = settings(max_examples=150, **SETTINGS)

DIR = Path(tempfile.mkdtemp(prefix="planecal-props-"))  # one file per reader, rewritten
atexit.register(shutil.rmtree, DIR, True)


def _robot_ok(r):
    assert np.all(np.isfinite(fk(r.kinematics, np.zeros(6))))
    assert np.all(np.isfinite(np.linalg.inv(r.coupling)))


def _scene_ok(s):
    for p in s.plates:
        assert np.all(np.isfinite(p.frame())) and np.all(np.isfinite(p.center()))
    assert s.robot is not None


def _params_ok(p):
    assert np.all(np.isfinite(p.to_vector())) and np.all(np.linalg.norm(p.planes, axis=1) > 0)


def _poses_ok(res):
    qe, plate, _ = res
    assert qe.shape == (len(plate), 6) and qe.dtype == np.int64


def _sidecar_ok(side):
    """What --resume does with it: settings, the scene they name, the random state."""
    from planecal.sampling.run import RunSettings
    if side.get("rng_state"):
        np.random.default_rng().bit_generator.state = side["rng_state"]
    rs = RunSettings.from_sidecar(side)  # InputError allowed, nothing else
    try:
        load_scene(rs.scene)
    except InputError as e:
        assert "\n" not in str(e) and "\r" not in str(e), str(e)


def _load_profile(path):
    from planecal.twin.profile import load_profile
    return load_profile(path, load_robot())


def _load_shapes(path):
    from planecal.model.geometry import load_shapes
    return load_shapes(path)


def _profile_ok(prof):
    """What a twin does with it: the options, a world's geometry, all finite."""
    from planecal.model.kinematics import fk as kin_fk
    from planecal.twin.profile import draw_geometry
    prof.options().joint_errors(load_robot())
    kin = draw_geometry(load_robot(), prof, np.random.default_rng(0))
    assert np.all(np.isfinite(kin_fk(kin, np.zeros(6))))


def _result():
    params = json.loads(repo_path("examples", "table10_params.json").read_text())
    std = {"joint_offsets_rad": [None, 1e-4, 1e-4, 1e-4, 1e-4, None],
           "planes": [{"n_tilde": [1e-3] * 3}],
           "sensor": {"origin_m": [1e-4] * 3, "phi_y_rad": 1e-3, "phi_z_rad": 1e-3}}
    result = {**params, "std": std, "residual_rms_mm": 0.01, "residual_rms_initial_mm": 1.2,
              "residual_max_mm": 0.03, "iterations": 5, "converged": True, "outliers": [3],
              "samples_used": 4, "identifiability": {"sigma_mm": 0.01}, "free": ["delta2"]}
    samples = repo_path("examples", "seed_samples.tsv")
    return result_document(result, provenance([("samples", samples)], "thesis_final", "mc70"))


def _shapes_ok(shapes):
    """What the twin and the checker do with them: every piece's meshes, closed."""
    from planecal.model.geometry import _piece
    for piece in shapes.pieces:
        for kind in ("visual", "collision"):
            assert _piece(piece.primitives, kind, 0.004).is_watertight


# format -> (reader, a valid document, the check of a successful read)
READERS = {
    ROBOT_FORMAT: (load_robot, json.loads(data_path("models", "mc70", "robot.json").read_text()),
                   _robot_ok),
    SCENE_FORMAT: (load_scene, json.loads(data_path("scenes", "three_plates.json").read_text()),
                   _scene_ok),
    PARAMS_FORMAT: (load_params,
                    json.loads(repo_path("examples", "table10_params.json").read_text()),
                    _params_ok),
    RESULT_FORMAT: (load_params, _result(), _params_ok),
    POSES_FORMAT: (load_poses, POSES, _poses_ok),
    SIDECAR_FORMAT: (load_sidecar, SIDECAR, _sidecar_ok),
    ERRORS_FORMAT: (_load_profile,
                    json.loads(data_path("models", "mc70", "errors", "realistic.json").read_text()),
                    _profile_ok),
    SHAPES_FORMAT: (_load_shapes,
                    json.loads(data_path("models", "mc70", "shapes.json").read_text()),
                    _shapes_ok),
}


def test_every_format_is_covered():
    """A format added to planecal.formats.MODELS needs its reader here."""
    assert set(READERS) == set(MODELS)


def outcome(name: str, text: str | bytes):
    """Write, read; assert the property. Returns 'ok' or 'refused' (for the record)."""
    reader, _, sane = READERS[name]
    path = DIR / (name.replace("/", "-") + ".json")
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    try:
        result = reader(path)
    except InputError as e:
        msg = str(e)
        assert "\n" not in msg and "\r" not in msg, msg
        assert msg.startswith(str(path)), msg
        return "refused"
    try:
        sane(result)
    except InputError:
        pass
    return "ok"


# ----- random bytes and random JSON ------------------------------------------------------------

@pytest.mark.parametrize("name", READERS)
@FEW
@given(data=st.binary(max_size=600))
def test_random_bytes(name, data):
    outcome(name, data)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-10**400, max_value=10**400)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=6) | st.dictionaries(st.text(max_size=12), inner, max_size=6),
    max_leaves=30)


@pytest.mark.parametrize("name", READERS)
@FEW
@given(value=json_values)
def test_random_json(name, value):
    outcome(name, json.dumps(value))


@pytest.mark.parametrize("name", READERS)
@FEW
@given(value=st.dictionaries(st.sampled_from(
    ["name", "dh", "encoder", "controller", "sensor", "plates", "robot", "joint_offsets_rad",
     "planes", "format", "counts", "settings", "seed", "scene", "samples_target"]),
    json_values, max_size=8))
def test_random_json_with_the_formats_keys(name, value):
    outcome(name, json.dumps(value))


# ----- near-valid documents ------------------------------------------------------------------

def paths_of(doc, prefix=()):
    """Every key/index path in doc (containers and leaves)."""
    out = []
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    for k, v in items:
        out.append(prefix + (k,))
        out.extend(paths_of(v, prefix + (k,)))
    return out


DEEP = "\u2063deep\u2063"  # replaced by 100,000 nested brackets after dumping
MUTATIONS = {
    "string": lambda v: "12.5",
    "bool": lambda v: True,
    "null": lambda v: None,
    "list": lambda v: [v, v],
    "object": lambda v: {"value": v},
    "nan": lambda v: math.nan,
    "inf": lambda v: -math.inf,
    "huge": lambda v: 1e308,
    "huge_int": lambda v: 10**400,
    "negative": lambda v: -v if isinstance(v, (int, float)) and not isinstance(v, bool) else -1,
    "zero": lambda v: 0,
    "empty": lambda v: [] if isinstance(v, list) else {},
    "deep": lambda v: DEEP,
}


@st.composite
def near_valid(draw, name):
    doc = copy.deepcopy(READERS[name][1])
    path = draw(st.sampled_from(paths_of(doc)))
    kind = draw(st.sampled_from(sorted(MUTATIONS) + ["delete"]))
    *head, last = path
    target = doc
    for k in head:
        target = target[k]
    if kind == "delete":
        del target[last]
    else:
        target[last] = MUTATIONS[kind](target[last])
    text = json.dumps(doc)
    return text.replace(json.dumps(DEEP), "[" * 100_000 + "]" * 100_000)


@pytest.mark.parametrize("name", READERS)
@MANY
@given(data=st.data())
def test_near_valid_documents(name, data):
    outcome(name, data.draw(near_valid(name)))


def test_valid_documents_are_read():
    """The starting points of the near-valid documents are themselves valid: the mutations
    above are what is refused, not the base."""
    for name, (_, doc, _) in READERS.items():
        assert outcome(name, json.dumps(doc)) == "ok", name


# ----- sample files ------------------------------------------------------------------------

SAMPLES = repo_path("examples", "seed_samples.tsv").read_bytes()


def sample_outcome(data: bytes):
    path = DIR / "samples.tsv"
    path.write_bytes(data)
    try:
        s = read_samples(path)
    except InputError as e:
        msg = str(e)
        assert "\n" not in msg and "\r" not in msg and msg.startswith(str(path)), msg
        return "refused"
    assert s.qe.shape == (len(s), 6) and np.all(np.isfinite(s.d_mm)) and np.all(s.d_mm > 0)
    assert np.all((s.qe >= 0) & (s.qe < 1 << 24)) and np.all(s.plate >= 0)
    return "ok"


@FEW
@given(data=st.binary(max_size=600))
def test_samples_random_bytes(data):
    sample_outcome(data)


@MANY
@given(line=st.integers(0, 5), column=st.integers(0, 7),
       field=st.one_of(st.text(max_size=10), st.sampled_from(
           ["", "nan", "-inf", "1e308", "-1", "16777216", "0", "0,0", "1_000", "\x00", "\u0663",
            "8388608.5", "92;5", "65", "95,000001"])),
       sep=st.sampled_from(["\t", " ", ",", ";"]))
def test_samples_near_valid(line, column, field, sep):
    rows = SAMPLES.decode("utf-8").splitlines()
    fields = rows[line].split("\t")
    if column < len(fields):
        fields[column] = field
    else:
        fields.append(field)
    rows[line] = sep.join(fields) if line and column == 7 else "\t".join(fields)
    sample_outcome("\r\n".join(rows).encode("utf-8", "surrogatepass"))


def test_the_seed_samples_are_read():
    assert sample_outcome(SAMPLES) == "ok"
