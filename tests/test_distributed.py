"""studies.distributed: the same runs, bit for bit, in this process, on a LocalCluster and
on a scheduler + workers started by hand; results streamed to a file that survives a
kill and resumes; quiet, bounded failures."""
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.studies import distributed as D
from planecal.studies import results as R
from planecal.studies.montecarlo import MCSettings, run_one

ST = MCSettings(mode="synthetic", samples=30, runs=6)
ITEMS = [(ST, k) for k in range(ST.runs)]
DASK = [str(Path(sys.executable).parent / "dask")]
pytestmark = pytest.mark.slow
ENV_BEFORE = {k: os.environ.get(k) for k in D.WORKER_ENV}


def _key(item):
    return item[1]


def assert_same_results(a: list, b: list):
    """Field by field; arrays by dtype, shape and bytes (bitwise, NaN included)."""
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert ra.keys() == rb.keys()
        for k in ra:
            va, vb = ra[k], rb[k]
            if isinstance(va, np.ndarray):
                assert isinstance(vb, np.ndarray), k
                assert (va.dtype, va.shape) == (vb.dtype, vb.shape), k
                assert va.tobytes() == vb.tobytes(), k
            else:
                assert type(va) is type(vb) or {type(va), type(vb)} <= {list, tuple}, k
                assert json.dumps(va) == json.dumps(vb), k


@pytest.fixture(scope="module")
def reference():
    with D.Engine(jobs=1) as eng:
        return eng.map(run_one, ITEMS)


@pytest.fixture(scope="module")
def cluster():
    with D.Engine(jobs=2) as eng:
        yield eng


# ----- the results file -------------------------------------------------------------------------

def test_encode_decode_round_trip_is_exact():
    rng = np.random.default_rng(0)
    obj = {"a": rng.normal(size=(3, 4)), "b": [np.arange(5, dtype=np.int64),
                                               {"c": np.zeros((0, 6)), "d/e~": np.float32(1.5)}],
           "f": np.array([np.nan, np.inf, -np.inf, 5e-324, 1 / 3]), "g": (1, "x", None),
           "h": np.array([True, False]), "i": np.int64(7), "j": np.array(2.5)}
    arrays, nonfinite = {}, {}
    enc = R.encode(obj, arrays, nonfinite=nonfinite)  # standard JSON: NaN, inf as null
    back = R.decode(json.loads(json.dumps(enc, allow_nan=False)), arrays, nonfinite)
    assert nonfinite == {"/f/0": "nan", "/f/1": "+inf", "/f/2": "-inf"}
    assert back["a"].tobytes() == obj["a"].tobytes()
    assert back["b"][0].dtype == np.int64 and back["b"][1]["c"].shape == (0, 6)
    assert back["b"][1]["d/e~"] == 1.5 and type(back["b"][1]["d/e~"]) is float
    assert back["f"].tobytes() == obj["f"].tobytes()
    assert back["g"] == [1, "x", None]
    assert back["h"].dtype == bool and back["i"] == 7 and back["j"].shape == ()
    with pytest.raises(TypeError, match="not a string"):
        R.encode({1: 2})
    with pytest.raises(TypeError, match="dtype"):
        R.encode({"x": np.array(["a"])})


def test_jobs_1_runs_here_without_dask(tmp_path):
    code = ("import sys\nfrom planecal.studies.distributed import Engine\n"
            "from planecal.studies.montecarlo import MCSettings, run_one\n"
            "st = MCSettings(mode='synthetic', samples=30, runs=2)\n"
            "with Engine(jobs=1) as e:\n"
            f"    r = e.map(run_one, [(st, 0), (st, 1)], out={str(tmp_path / 'r.jsonl')!r})\n"
            "print(len(r), [m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "2 []"


def test_results_file_streams_resumes_and_refuses_other_settings(tmp_path, reference):
    out = tmp_path / "runs.jsonl"
    seen = []
    with D.Engine(jobs=1) as eng:
        first = eng.map(run_one, ITEMS[:4], key=_key, out=out, header={"runs": 6},
                        on_result=lambda i, r: seen.append((i, out.read_text().count("\n"))))
        # each result is on disk before the caller sees it
        assert seen == [(i, i + 2) for i in range(4)]
        assert_same_results(first, reference[:4])
        with pytest.raises(InputError, match="exists"):
            eng.map(run_one, ITEMS, key=_key, out=out, header={"runs": 6})
        with pytest.raises(InputError, match=r"header\.runs: 6 in the file, 7 now"):
            eng.map(run_one, ITEMS, key=_key, out=out, header={"runs": 7}, resume=True)
        # a torn last line (power loss) is dropped; the runs already there are not rerun
        with open(out, "a") as f:
            f.write('{"key": 4, "resu')
        calls = []
        res = eng.map(run_one, ITEMS, key=_key, out=out, header={"runs": 6}, resume=True,
                      on_result=lambda i, r: calls.append(i))
    assert calls == [0, 1, 2, 3, 4, 5]  # 0-3 read back first, in order, then 4, 5 run
    assert_same_results(res, reference)
    lines = out.read_text().splitlines()
    assert len(lines) == 7 and [json.loads(ln)["key"] for ln in lines[1:]] == list(range(6))
    header, back = R.read_results(out)
    assert header == {"runs": 6}
    assert_same_results([r for _, r in back], reference)
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"format": "something else"}\n')
    with D.Engine(jobs=1) as eng, pytest.raises(InputError, match="not a planecal results"):
        eng.map(run_one, ITEMS, out=bad, resume=True)


def test_duplicate_keys_are_refused():
    with D.Engine(jobs=1) as eng, pytest.raises(ValueError, match="key 0"):
        eng.map(run_one, ITEMS[:2], key=lambda it: 0)


# ----- the same numbers on every engine ---------------------------------------------------------

def test_local_cluster_gives_the_same_results(cluster, reference, tmp_path):
    assert cluster.slots == 2 and cluster.describe().startswith("local Dask cluster")
    done = []

    class Count:
        def step(self, k=1):
            done.append(k)

    res = cluster.map(run_one, ITEMS, progress=Count())
    assert_same_results(res, reference)
    assert done == [1] * len(ITEMS)
    # through a results file the returned values are the decoded lines: still identical
    assert_same_results(cluster.map(run_one, ITEMS, key=_key, out=tmp_path / "r.jsonl"),
                        reference)


def test_local_cluster_workers_have_one_blas_thread_and_no_gl(cluster):
    envs = cluster.worker_env()
    assert len(envs) == 2 and len({e["pid"] for e in envs}) == 2
    for e in envs:
        assert {k: e[k] for k in D.WORKER_ENV} == D.WORKER_ENV
    # dask's settings for the workers (no profiler, slower housekeeping), not this process's
    for c in cluster.client.run(D._worker_config).values():
        assert c == D.WORKER_CONFIG
    import dask
    assert dask.config.get("distributed.worker.profile.enabled") is True
    # the workers' environment is not left in this process
    assert {k: os.environ.get(k) for k in D.WORKER_ENV} == ENV_BEFORE


def test_an_error_in_a_run_stops_the_map_with_it(cluster, tmp_path):
    out = tmp_path / "r.jsonl"
    with pytest.raises(TypeError, match="unsupported operand"):  # the worker's own error
        cluster.map(run_one, ITEMS[:2] + [(ST, "x")], key=lambda it: str(it[1]), out=out)
    # whatever completed before is on disk, whole lines
    assert out.read_bytes().endswith(b"\n")


def _stop(procs):
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)  # the group this test started
            p.wait(timeout=10)


@pytest.fixture(scope="module")
def by_hand(tmp_path_factory):
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1, started as a user
    would: the scheduler and the first worker after ``export $(planecal worker-env)`` (the
    README's commands), the second worker without it (a user who forgot): the scheduler's
    address. Bounded waits; stopped (and, past 20 s, killed) at the end of the module
    whatever happened."""
    d = tmp_path_factory.mktemp("dask")
    sfile = d / "scheduler.json"
    printed = subprocess.run([str(Path(sys.executable).parent / "planecal"), "worker-env"],
                             capture_output=True, text=True, check=True).stdout.split()
    env = {**os.environ, **dict(line.split("=", 1) for line in printed)}
    plain = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    log = open(d / "dask.log", "w")
    procs = [subprocess.Popen(DASK + ["scheduler", "--host", "127.0.0.1", "--port", "0",
                                      "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
                                      "--scheduler-file", str(sfile)],
                              stdout=log, stderr=log, env=env, start_new_session=True)]
    try:
        deadline = time.monotonic() + 60
        while not sfile.exists() or not sfile.read_text().strip():
            assert time.monotonic() < deadline, "the scheduler did not start within 60 s"
            assert procs[0].poll() is None, (d / "dask.log").read_text()
            time.sleep(0.2)
        addr = json.loads(sfile.read_text())["address"]
        assert addr.startswith("tcp://127.0.0.1:")
        for e in (env, plain):
            procs.append(subprocess.Popen(
                DASK + ["worker", addr, "--nthreads", "1", "--no-dashboard", "--host",
                        "127.0.0.1", "--dashboard-address", "127.0.0.1:0"], stdout=log,
                stderr=log, env=e, start_new_session=True))
        with D.Engine(scheduler=addr, connect_timeout_s=60) as eng:
            eng.client.wait_for_workers(2, timeout=60)
        yield addr
    finally:
        _stop(procs[1:])
        _stop(procs[:1])
        log.close()


def test_scheduler_and_workers_started_by_hand_give_the_same_results(by_hand, reference):
    notes = []
    with D.Engine(scheduler=by_hand, connect_timeout_s=60, notify=notes.append) as eng:
        assert eng.slots == 2
        for e in eng.worker_env():  # MUJOCO_GL: set by the engine's plugin where missing
            assert e["OPENBLAS_NUM_THREADS"] == "1" and e["MUJOCO_GL"] == "disable"
        # the worker started without planecal's dask settings is named, with the remedy
        configs = sorted(eng.client.run(D._worker_config).values(), key=str)
        assert configs[0] == D.WORKER_CONFIG
        assert configs[1]["distributed.worker.profile.enabled"] is True
        assert eng.untuned == 1
        assert notes == ["1 of the scheduler's workers run without planecal's dask "
                         "settings (dask's profiler on: ~10 % slower); start them after "
                         "'export $(planecal worker-env)'"]
        assert eng.describe() == (f"Dask scheduler {by_hand}: 2 worker threads (1 without "
                                  "planecal's dask settings)")
        res = eng.map(run_one, ITEMS)
    assert_same_results(res, reference)


def test_unreachable_scheduler_is_one_line_error():
    import socket
    with socket.socket() as s:  # a free port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(InputError) as e:
        with D.Engine(scheduler=f"tcp://127.0.0.1:{port}", connect_timeout_s=2):
            pass
    assert str(e.value) == (f"--scheduler tcp://127.0.0.1:{port}: no Dask scheduler "
                            "answered within 2 s (OSError)")
    with pytest.raises(InputError, match="exclude each other"):
        D.Engine(jobs=2, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(InputError, match="at least 1"):
        D.Engine(jobs=0)


# ----- killed and resumed -----------------------------------------------------------------------

KILLED = """
import os, sys, time
from planecal.studies.distributed import Engine
from planecal.studies.montecarlo import MCSettings, run_one

def stop_after_3(i, r, seen=[]):
    seen.append(i)
    if len(seen) == 3:
        print("three", flush=True)
        time.sleep(600)  # the test kills us here

if __name__ == "__main__":
    import signal
    # Ctrl-C's KeyboardInterrupt whatever the test run was started with: a shell starts a
    # background job ignoring SIGINT, the ignoring is inherited, and then the SIGINT below
    # never arrives (`.ci/run &` hung here for 60 s)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    st = MCSettings(mode="synthetic", samples=30, runs=6)
    with Engine(jobs=2) as eng:
        print("pids", *[e["pid"] for e in eng.worker_env()], flush=True)
        eng.map(run_one, [(st, k) for k in range(6)], key=lambda it: it[1], out=sys.argv[1],
                header={"study": "test"}, resume=True, on_result=stop_after_3)
"""


def _alive(pid):
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_killed_map_resumes_to_the_uninterrupted_results(tmp_path, reference, sig):
    script = tmp_path / "killed.py"
    script.write_text(KILLED)
    out = tmp_path / "runs.jsonl"
    p = subprocess.Popen([sys.executable, str(script), str(out)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        pids = [int(x) for x in p.stdout.readline().split()[1:]]
        assert len(pids) == 2, p.stderr.read() if p.poll() is not None else pids
        assert p.stdout.readline().strip() == "three"
        os.kill(p.pid, sig)
        p.wait(timeout=60)
        deadline = time.monotonic() + 30  # the workers go with their parent
        while any(_alive(w) for w in pids):
            assert time.monotonic() < deadline, "worker processes outlived the killed map"
            time.sleep(0.2)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=10)
        p.stdout.close()
        err = p.stderr.read()
        p.stderr.close()
    # no log line from dask, killed or interrupted (only the script's own KeyboardInterrupt)
    assert not re.search(r"distributed\.[\w.]+ - [A-Z]+ - ", err), err
    if sig == signal.SIGINT:
        assert err.rstrip().endswith("KeyboardInterrupt")
    data = out.read_bytes()
    assert data.endswith(b"\n") and data.count(b"\n") == 4  # header + 3 whole lines
    with D.Engine(jobs=2) as eng:
        res = eng.map(run_one, ITEMS, key=_key, out=out, header={"study": "test"},
                      resume=True)
    assert_same_results(res, reference)
    assert sorted(json.loads(ln)["key"] for ln in out.read_text().splitlines()[1:]) == \
        list(range(6))


# ----- the studies and their commands on the engine ---------------------------------------------

MC_ARGS = ["montecarlo", "--mode", "synthetic", "--runs", "6", "--samples", "30", "--seed", "77"]


def _mc(d, name, *extra) -> dict:
    from planecal.cli import main
    out = d / f"{name}.json"
    assert main(MC_ARGS + ["--out", str(out), *extra]) == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def mc_jobs1(tmp_path_factory):
    """`planecal montecarlo ... --jobs 1`: the reference document."""
    return _mc(tmp_path_factory.mktemp("mc"), "jobs1", "--jobs", "1")


# a small realistic world leaves a parameter with no finite reported std (analyze's nanmean)
@pytest.mark.filterwarnings("ignore:Mean of empty slice:RuntimeWarning")
def test_montecarlo_run_errors_are_the_same_on_a_local_cluster(cluster):
    """Twin runs in the realistic world (its ticks, backlash, thermal state and gear phases
    in a worker process) and synthetic runs: analyze's run_errors, in run order, bit for bit
    the same on 2 workers as in this process."""
    from planecal.studies.montecarlo import analyze, run_many
    for st in (MCSettings(errors="realistic", samples=30, runs=2, seed=31),
               MCSettings(mode="synthetic", samples=30, runs=6, seed=77)):
        here = analyze(run_many(st, 1, quiet=True), st)
        there = analyze(run_many(st, cluster, quiet=True), st)
        assert len(here["run_errors"]) == st.runs
        assert json.dumps(there["run_errors"]) == json.dumps(here["run_errors"])
        assert json.dumps(there) == json.dumps(here)  # and so every figure of the analysis


def test_montecarlo_command_default_local_cluster_gives_the_jobs_1_document(
        tmp_path, mc_jobs1, capsys):
    doc = _mc(tmp_path, "default")  # no --jobs: a LocalCluster, one worker per core
    err = capsys.readouterr().err
    assert f"local Dask cluster: {os.cpu_count()} worker processes" in err
    assert "N=30 6/6" in err  # the progress reached the end as the runs completed
    assert doc["run_errors"] == mc_jobs1["run_errors"] and doc == mc_jobs1
    lines = (tmp_path / "default.runs.jsonl").read_text().splitlines()
    assert sorted(json.loads(ln)["key"] for ln in lines[1:]) == list(range(6))


def test_montecarlo_command_on_scheduler_started_by_hand(by_hand, tmp_path, mc_jobs1, capsys):
    doc = _mc(tmp_path, "sched", "--scheduler", by_hand)
    assert f"Dask scheduler {by_hand}: 2 worker threads" in capsys.readouterr().err
    assert doc["run_errors"] == mc_jobs1["run_errors"] and doc == mc_jobs1


def test_montecarlo_command_resume_runs_only_the_missing_runs(tmp_path, mc_jobs1, capsys):
    from planecal.cli import main
    _mc(tmp_path, "m", "--jobs", "1")
    rfile = tmp_path / "m.runs.jsonl"
    lines = rfile.read_text().splitlines()
    assert len(lines) == 7
    # keep runs 0-2, and mark run 0's result: a resumed study must read it back, not rerun it
    rec = json.loads(lines[1])
    assert rec["key"] == 0
    rec["result"]["err"][0] = 0.5
    rfile.write_text("\n".join([lines[0], json.dumps(rec)] + lines[2:4]) + "\n")
    capsys.readouterr()
    # an existing results file is continued or replaced, never silently appended to
    assert main(MC_ARGS + ["--jobs", "1", "--out", str(tmp_path / "m.json")]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "m.runs.jsonl: results of an earlier run exist (--resume to continue them, --force "
        "to start afresh)")
    doc = _mc(tmp_path, "m", "--jobs", "1", "--resume")
    assert doc["run_errors"][0][0] == 0.5  # read back
    assert doc["run_errors"][0][1:] == mc_jobs1["run_errors"][0][1:]
    assert doc["run_errors"][1:] == mc_jobs1["run_errors"][1:]  # 1, 2 read, 3-5 run again
    keys = [json.loads(ln)["key"] for ln in rfile.read_text().splitlines()[1:]]
    assert keys == [0, 1, 2, 3, 4, 5]
    # --force starts afresh: run 0 is run again
    assert _mc(tmp_path, "m", "--jobs", "1", "--force")["run_errors"] == mc_jobs1["run_errors"]
    # --results names the file; --resume without any file is refused
    assert _mc(tmp_path, "n", "--jobs", "1", "--results", str(tmp_path / "r.jsonl")) == \
        mc_jobs1
    assert (tmp_path / "r.jsonl").exists() and not (tmp_path / "n.runs.jsonl").exists()
    assert main(MC_ARGS + ["--jobs", "1", "--resume"]) == 2
    assert "--resume needs a results file" in capsys.readouterr().err


def test_engine_options_are_checked_before_any_run(capsys):
    from planecal.cli import main
    assert main(MC_ARGS + ["--jobs", "0"]) == 2
    assert "argument --jobs: 0 is not a count (1 .. " in capsys.readouterr().err
    assert main(MC_ARGS + ["--jobs", "2", "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "exclude each other" in capsys.readouterr().err


def test_bootstrap_fits_are_the_same_on_a_local_cluster(cluster, tmp_path):
    """Subset r of size s is drawn from (seed, s, r) by the run itself: the same fits on 2
    workers as here, through a results file and resumed."""
    from planecal.estimation.calibrate import CalibrationSettings
    from planecal.model.scene import load_scene, nominal_params
    from planecal.studies.bootstrap import BootstrapSettings, Pool, bootstrap
    from planecal.twin.synthetic import synthetic_samples
    from planecal.twin.truth import draw_truth
    scene = load_scene("thesis_final")
    qe, d, plate = synthetic_samples(scene, draw_truth(scene, 3), 120,
                                     np.random.default_rng(1), noise_m=20e-6)
    problem = Pool(scene.robot, qe, d, plate, nominal_params(scene), CalibrationSettings())
    st = BootstrapSettings((30, 60), 4, seed=5)
    here = bootstrap(problem, st, 1, quiet=True)
    out = tmp_path / "b.jsonl"
    there = bootstrap(problem, st, cluster, quiet=True, results=out)
    assert json.dumps(R.encode(there)) == json.dumps(R.encode(here))
    header, fits = R.read_results(out)
    assert sorted(k for k, _ in fits) == [[s, r] for s in (30, 60) for r in range(4)]
    assert header["study"] == "bootstrap" and header["seed"] == 5
    more = bootstrap(problem, BootstrapSettings((30, 60), 6, seed=5), cluster, quiet=True,
                     results=out, resume=True)  # two more subsets per size: 4 fits run
    assert len(R.read_results(out)[1]) == 12
    assert more["sizes"][0]["fits"] == 6


def test_a_close_that_runs_out_kills_the_local_workers():
    # Engine.close bounds the client's and the cluster's close (CLOSE_TIMEOUT_S each), so
    # a stopped study exits even where the scheduler no longer answers; where the
    # cluster's close runs out, its worker processes are killed, not left behind.
    class Slow:
        def __init__(self):
            self.timeouts = []

        def close(self, timeout=None):
            self.timeouts.append(timeout)
            raise TimeoutError("a close that does not finish")

    worker = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        eng = D.Engine(jobs=2)
        eng.client, eng._cluster, eng._pids = Slow(), Slow(), [worker.pid]
        client, cluster = eng.client, eng._cluster
        eng.close()
        assert worker.wait(timeout=10) == -signal.SIGKILL
        assert client.timeouts == [D.CLOSE_TIMEOUT_S] and cluster.timeouts == [D.CLOSE_TIMEOUT_S]
        assert eng.client is None and eng._pids == []
    finally:
        if worker.poll() is None:
            worker.kill()
            worker.wait()
