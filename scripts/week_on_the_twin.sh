#!/usr/bin/env bash
# docs/HISTORY.md's worked week on the twin, every step a planecal command:
#     scripts/week_on_the_twin.sh [FOLDER]   (from the checkout; writes FOLDER, default week/)
set -u
export PATH="${PLANECAL_BIN:-$PWD/.venv/bin}:$PATH"  # planecal on PATH
mkdir -p "${1:-week}" && cd "${1:-week}" || exit 2
rm -f planecal.db ./*.tsv ./*.tsv.json; rm -rf report_fri  # a fresh week in FOLDER
step() { echo; echo "\$ $*"; "$@"; echo "[exit $?]"; }
quiet() { echo; echo "\$ $*"; "$@" > /dev/null 2>&1; echo "[exit $?]"; }
# Monday: commissioning. A 150-sample run in the cell's world t0 (the realistic twin,
# truth seed 1; --truth-out keeps the world), calibrated into the history, exported.
quiet planecal rehearse --samples 150 --seed 1 --out mon.tsv --truth-out t0.json -q
step planecal calibrate mon.tsv --out r_mon.json --note "monday: commissioning"
step planecal export r_mon.json --out fd11_mon.json
# the regression pose list and its rehearsal on the twin
quiet planecal plan --samples 30 --out P30.json -q
quiet planecal rehearse --poses P30.json --truth t0.json --seed 50 --out twin_P30.tsv -q
# Tuesday to Friday mornings: a short run of 30 random poses, checked
for k in 11 12 13 14 15; do
  quiet planecal rehearse --samples 30 --seed $k --truth t0.json --out day_$k.tsv -q
  step planecal check day_$k.tsv --against r_mon.json --note "morning check"
done
# Friday noon: J3's motor replaced; the new zero is 0.5 mrad off (a copy of t0 edited)
python3 -c "import json; d = json.load(open('t0.json')); d['joint_offsets_rad'][2] += 5e-4; json.dump(d, open('t1.json', 'w'), indent=2)"
quiet planecal rehearse --samples 30 --seed 16 --truth t1.json --out fri.tsv -q
step planecal check fri.tsv --against r_mon.json --note "after the J3 motor change"
# the regression poses on the cell (here the twin in t1 stands for the real robot)
quiet planecal rehearse --poses P30.json --truth t0.json --seed 52 --out tue_P30.tsv -q
step planecal compare tue_P30.tsv --rehearsal twin_P30.tsv --params r_mon.json
quiet planecal rehearse --poses P30.json --truth t1.json --seed 51 --out fri_P30.tsv -q
step planecal compare fri_P30.tsv --rehearsal twin_P30.tsv --params r_mon.json --report report_fri --rrd compare_fri.rrd --out compare_fri.json
# recalibration after the maintenance; what changed
quiet planecal rehearse --samples 150 --seed 2 --truth t1.json --out fri150.tsv -q
step planecal calibrate fri150.tsv --out r_fri.json --note "friday: after the J3 motor"
step planecal history diff 1 11
# the new motor goes back out: Monday's offsets again
step planecal history rollback 1 --out fd11_rollback.json
step planecal history list
