"""The test's processes: start it, stream its output, end its whole tree, reap what dies.

``supervisor`` runs one test; ``capture`` fans its output out; ``tree`` and ``reaper``
find and end what it left behind; ``proc`` is the one reader of ``/proc``.
"""
