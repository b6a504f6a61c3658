"""Reports a person reads: ``write_report(result, out_dir)`` writes ``out_dir/index.html``
with PNG figures beside it (matplotlib) for any result file planecal writes:

=============  ============================================  ==========================
kind           written by                                    module
=============  ============================================  ==========================
calibration    ``calibrate --out``, ``demo`` (result.json)   ``report.calibration``
montecarlo     ``montecarlo --out``                          ``report.montecarlo``
bootstrap      ``bootstrap --out``                           ``report.bootstrap``
validation     ``validate --out``                            ``report.validation``
plan           ``plan --out`` (a pose list)                  ``report.planning``
sweep          ``sweep --out DIR`` (DIR/sweep.json)          ``report.sweep``
compare        ``compare --out`` (twin against real)         ``report.compare``
=============  ============================================  ==========================

The kind comes from the file's ``format`` field (``"<name>/<version>"``) when it has one,
else from its content (files written before the field existed). Every page ends with
the provenance: what the file records of its own origin, the inputs the report read, and
the report's own date and planecal version. The report reads result *files* (JSON), not
the objects of the code that wrote them.
"""
from __future__ import annotations

import importlib
from datetime import datetime, timezone
from pathlib import Path

from planecal.base.errors import InputError
from planecal.present.report.inputs import Context, sha256
from planecal.present.report.page import Page

KINDS = {"calibration": "calibration", "montecarlo": "montecarlo", "bootstrap": "bootstrap",
         "validation": "validation", "plan": "planning",
         "sweep": "sweep", "compare": "compare"}  # kind -> module in this package

# format names (the part before "/") and the kind they hold
FORMATS = {"planecal-result": "calibration", "planecal-montecarlo": "montecarlo",
           "planecal-bootstrap": "bootstrap", "planecal-validation": "validation",
           "planecal-validate": "validation", "planecal-poses": "plan", "planecal-plan": "plan",
           "planecal-sweep": "sweep", "planecal-compare": "compare"}
READ_VERSIONS = {"planecal-validate": {2, 3}}  # the versions reported (default: 1 only)
# why a version is no longer read, in one line
_FLANGE_AP = ("written before AP was measured at the tool point (its ap_after_mm is the "
              "flange's): run planecal validate again")
RETIRED = {"planecal-validate/1": _FLANGE_AP, "planecal-validation/1": _FLANGE_AP}


def detect_kind(doc, where: str = "result") -> str:
    """The kind of a result document (module docstring); InputError if it is none."""
    if not isinstance(doc, dict):
        raise InputError(f"{where}: a result file is a JSON object")
    fmt = doc.get("format")
    if fmt is not None:
        name, _, version = str(fmt).partition("/")
        if name in FORMATS:
            if str(fmt) in RETIRED:
                raise InputError(f"{where}: format {fmt}: {RETIRED[str(fmt)]}")
            versions = READ_VERSIONS.get(name, {1})
            if not version.isdigit() or int(version) not in versions:
                raise InputError(f"{where}: format {fmt}: this planecal reports version(s) "
                                 f"{', '.join(map(str, sorted(versions)))} of {name}")
            return FORMATS[name]
    if "iso" in doc and "gauge" in doc:  # a validation from before the format field
        raise InputError(f"{where}: a validate result without a format field: "
                         + RETIRED["planecal-validate/1"])
    kind = _kind_from_content(doc)
    if kind is None:
        what = f"format {fmt}" if fmt is not None else "its content"
        raise InputError(f"{where}: not a result planecal can report on (by {what}; known: "
                         f"calibration, montecarlo, bootstrap, validate, plan and compare results)")
    return kind


def _kind_from_content(doc: dict) -> str | None:
    if "run_errors" in doc or "chi2_offsets_reported" in doc:
        return "montecarlo"
    if "sizes" in doc and "pool" in doc:
        return "bootstrap"
    if "predicted_std_planned" in doc and "counts" in doc:
        return "plan"
    if "joint_offsets_rad" in doc and ("identifiability" in doc or "residual_rms_mm" in doc):
        return "calibration"
    return None


def write_report(result, out_dir, samples=None, scene: str | None = None) -> Path:
    """Write the report of ``result`` (a path to a result file, or its dict) into
    ``out_dir`` (created if needed; its parent must exist): index.html and its PNG
    figures. ``samples``: sample file paths (or a ``planecal.io.samples.Samples``) of a
    calibration result, for the per-sample figures (default: the inputs the result
    records); ``scene``: a scene name or path (default: the result's, else the default
    scene). The page and figures are made in a temporary folder beside ``out_dir`` and
    moved in when all are written: a result that cannot be reported leaves nothing.
    Returns index.html's path."""
    import os
    import shutil
    import tempfile
    source = None
    if isinstance(result, (str, Path)):
        from planecal.io.params import load_json
        source = Path(result)
        doc = load_json(source)
    else:
        doc = result
    where = str(source) if source else "result"
    kind = detect_kind(doc, where)
    check_document(doc, kind, where)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a directory")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{out}: directory {parent} does not exist")
    _refuse_overwriting_inputs(out, source, samples)
    module = importlib.import_module(f"planecal.present.report.{KINDS[kind]}")
    try:
        stage = Path(tempfile.mkdtemp(dir=parent, prefix=f".{out.name[:64]}.", suffix=".tmp"))
    except OSError as e:
        raise InputError(f"{out}: cannot create the report directory ({e.strerror})") from None
    try:
        ctx = Context(doc=doc, out_dir=stage, source=source, samples=samples, scene=scene)
        try:
            page = module.build(ctx)
        except (KeyError, TypeError, ValueError, IndexError) as e:
            raise InputError(f"{where}: not a complete {kind} result ({type(e).__name__}: "
                             f"{e})") from None
        provenance_section(page, ctx, kind)
        page.write(stage)
        out.mkdir(exist_ok=True)
        for f in sorted(stage.iterdir()):
            os.replace(f, out / f.name)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return out / "index.html"


def check_document(doc: dict, kind: str, where: str) -> None:
    """A result file that names its format is validated against it before anything is
    drawn (``formats.params.ResultFile``: a field of the wrong type, NaN where a number
    belongs): one line naming the field."""
    if kind == "calibration" and doc.get("format") is not None:
        from planecal.formats.base import validate
        from planecal.formats.params import ResultFile
        validate(ResultFile, doc, where, "result file")


def _refuse_overwriting_inputs(out: Path, source: Path | None, samples) -> None:
    inputs = [source] if source is not None else []
    if isinstance(samples, (list, tuple)):
        inputs += [Path(p) for p in samples]
    for p in inputs:
        if p.resolve().parent == out.resolve() and (p.name == "index.html" or p.suffix == ".png"):
            raise InputError(f"{p}: the report would overwrite this input; choose another --out")


def provenance_section(page: Page, ctx: Context, kind: str) -> None:
    from planecal import __version__
    doc = ctx.doc
    sec = page.section("Provenance")
    rows = []
    if ctx.source is not None:
        rows.append(["result file", str(ctx.source)])
        rows.append(["result file SHA-256", sha256(ctx.source)])
    rows.append(["kind", kind + (f" (format {doc['format']})" if "format" in doc
                                 else " (recognised by its content: the file has no format field)")])
    prov = doc.get("provenance")
    if isinstance(prov, dict):
        for k, v in prov.items():
            if k != "inputs":
                rows.append([f"result: {k}", _short(v)])
    for key in ("scene", "seed", "samples", "runs", "pool", "repeats"):
        if key in doc and not isinstance(doc[key], (dict, list)):
            rows.append([f"result: {key}", _short(doc[key])])
    if isinstance(doc.get("settings"), dict):
        rows.append(["result: settings", ", ".join(f"{k}={_short(v)}"
                                                   for k, v in doc["settings"].items())])
    rows.append(["report written (UTC)",
                 datetime.now(timezone.utc).isoformat(timespec="seconds")])
    rows.append(["report by", f"planecal {__version__}"])
    sec.table(["", ""], rows, left=2)
    inputs = prov.get("inputs") if isinstance(prov, dict) else None
    if isinstance(inputs, list) and inputs:
        sec.text("Inputs the result records:")
        sec.table(["role", "path", "bytes", "SHA-256"],
                  [[i.get("role", ""), i.get("path", ""), i.get("bytes", ""), i.get("sha256", "")]
                   for i in inputs if isinstance(i, dict)], left=2)
    elif "provenance" not in doc:
        sec.note("This result file records no provenance (inputs, version, date).")
    if ctx.used_inputs:
        sec.text("Files this report read besides the result:")
        sec.table(["role", "path", "SHA-256"],
                  [[u["role"], u["path"], u["sha256"]] for u in ctx.used_inputs], left=2)


def _short(v) -> str:
    s = str(v)
    return s if len(s) <= 200 else s[:197] + "..."
