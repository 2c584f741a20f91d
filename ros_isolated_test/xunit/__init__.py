"""xUnit result files: read any producer's file safely, make it canonical, write it whole.

``model`` (cases and suites), ``reader`` (hostile-safe streaming read, by stage:
``sanitiser`` and ``markup``, ``safe_parser``, ``builder``, into the ``raw`` model),
``normalise`` (per-producer fixes), ``validate`` (render and check against ``schemas/junit.xsd``),
``serialise`` (the bytes, without lxml), ``result_file`` (one test's file through its
life), ``report`` (summaries of many files).
"""
