"""xUnit result files: read any producer's file safely, make it canonical, write it whole.

``model`` (cases and suites), ``reader`` (hostile-safe streaming read, by stage:
``sanitiser`` and ``markup``, ``safe_parser``, ``builder``, into the ``raw`` model),
``normalise`` (per-producer fixes), ``validate`` (render and check against ``schemas/junit.xsd``),
``serialise`` (the bytes, without lxml), ``attempts`` and ``gitlab`` (reruns merged,
GitLab's rules), ``result_file`` (one test's file through its life, with ``placeholder``
and ``timeline``), ``canonical`` (any file made canonical). Many files (a tree, its
counts, its page) are ``report``'s, the package above this one.
"""
