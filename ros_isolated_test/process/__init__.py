"""The test's processes: start it, stream its output, end its whole tree, reap what dies.

``supervisor`` runs one test: ``spawn`` starts it (``fork_exec``: tethered, so it dies
with the runner), ``signals`` passes the runner's signals on, ``sweep`` ends what it left;
``capture`` fans its output out; ``tree`` and ``reaper`` find and reap its processes;
``proc`` is the one reader of ``/proc``; ``namespace`` gives a test namespaces of its own,
``namespace_diagnosis`` says why a host refuses them.
"""
