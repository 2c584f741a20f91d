"""A test history: every run's results in one SQLite file, to tell flaky from broken.

``store`` opens and shapes the database, ``record`` puts the result trees of one run in
it, ``stats`` reads a window of runs back per test, ``merge`` joins databases made on
several machines, ``export`` writes what other tools read (JSON lines, a durations file).
Nothing here is on a test's path: the runner imports it only when asked to record.
"""
