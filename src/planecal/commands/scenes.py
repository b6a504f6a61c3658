"""planecal scenes: the scenes (cells) planecal knows, one a line: name, robot, plates (and
"+ length" where a length reference fixes the arm's scale) and
description (scenes/*.json; any other scene is given by its path). A scene that cannot be
read (a broken file in $PLANECAL_HOME/scenes) does not hide the others: they are listed,
and the command ends with one line naming the first bad one and why (exit 2)."""
from __future__ import annotations


def add_arguments(p):
    p.add_argument("--json", action="store_true", help="print them as JSON")


def run(args) -> int:
    import json

    from planecal.base.errors import InputError

    from planecal.base.paths import data_folder
    from planecal.model.scene import load_scene

    rows = []
    folder = data_folder("scenes")  # a one-line error if it is missing or empty
    paths = sorted(folder.glob("*.json"))
    if not paths:
        raise InputError(f"{folder}: no scenes (*.json) in it")
    bad = []
    for path in paths:
        try:
            s = load_scene(path)
        except InputError as e:
            bad.append(e)
            continue
        rows.append({"name": path.stem, "plates": len(s.plates),
                     "length_references": len(s.references),
                     "robot": s.robot.folder.name if s.robot.folder else s.robot.name,
                     "robot_name": s.robot.name, "description": s.description or "",
                     "path": str(path)})
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        _table(rows)
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise InputError(f"{bad[0]}{more}; the other scenes are listed")
    return 0


def _table(rows: list[dict]) -> None:
    if not rows:
        return
    w = max(len(r["name"]) for r in rows)
    wr = max(len(r["robot"]) for r in rows)
    for r in rows:  # the description's first sentence
        first = r["description"].split(". ")[0].rstrip(".")
        first = first if len(first) <= 80 else first[:77] + "..."
        ref = "+ length" if r["length_references"] else "        "
        print(f"{r['name']:<{w}}  {r['robot']:<{wr}}  {r['plates']} plate"
              f"{'s' if r['plates'] != 1 else ' '} {ref}  {first}")
    print("(any other scene: give its JSON path; planecal scenes --json for the details)")
