"""The largest counts planecal takes, one place for the command-line options
(``commands.value_options.count``) and the files that hold counts (a sweep's spec): a
value beyond them is refused in one line (exit 2), never a run that does not end. The
README lists them ("Bounds")."""

MAX_SAMPLES = 100_000  # samples of one run: ~3 weeks of robot time at 19 s a sample
MAX_RUNS = 100_000  # runs of a study (Monte Carlo runs, bootstrap subsets, sweep runs)
MAX_CANDIDATES = 100_000  # candidate poses of a plan (its default: 1,500)
MAX_ITERATIONS = 10_000  # solver iterations, ISO cycles, gauge repeats
MAX_TRIES = 1_000_000  # laser reads, pose attempts, laser errors in a row
JOBS_PER_CORE = 4  # a local cluster's worker processes per core, at most
SEED_MAX = 2**63 - 1  # seeds: 0 .. 2**63 - 1
