"""Splitting one workspace's tests over N CI machines: each runs its share, none sees another.

The CI system's parallel jobs are the machines (a GitHub Actions matrix, GitLab's
``parallel:``, a Kubernetes Indexed Job); nothing here schedules or talks between them.
Each machine is told its share (``spec``: ``ROS_ISOLATED_TEST_SHARD=I/N``) and reads the
same durations file (``durations``: test ``identity`` -> seconds, from earlier runs);
from those alone every machine, and every runner on it deciding for its one test,
computes the same ``plan`` (longest first onto the least loaded share; a test the file
does not know by the SHA-256 of its identity, ``digest``), so every test runs in exactly
one share. ``selection`` is what the entry points call; ``view`` prints a plan for
``ros-isolated-test shard --plan``.

Standard library only and below every other layer but the bottom one: the runner, the
pytest plugin and the report all import it. On a test's path it loads no ``typing``, no
``dataclasses`` and no ``hashlib`` (OpenSSL); ``json`` only when a durations file is read.
"""
