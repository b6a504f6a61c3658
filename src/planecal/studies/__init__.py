"""Statistical studies of the calibration (issue 6): subset resampling of a pool
(``bootstrap``, seed 9.3), Monte Carlo on the twin against the Cramer-Rao bound
(``montecarlo``), D-optimal pose planning (``planning``), ISO 9283 pose accuracy and the
gauge-block test on the twin (``validation``), and replaying recorded samples in the twin
(``replay``). Each study is a pure function of (scene, seed, settings); the commands
``planecal bootstrap|montecarlo|plan|validate|replay`` print a report and write JSON.
See docs/STUDIES.md.
"""
