"""The runner: one flow from a parsed request to an exit code.

Entry points (``ros_isolated_test.cli``, ``ament``) build a ``request`` from settings read
once (``settings``) -> environment policy (``environment``, ``discovery``) -> domain
coordinator (``ros_isolated_test.domain_coordinator``) -> process supervisor
(``ros_isolated_test.process``) -> result file (``ros_isolated_test.xunit``) -> exit
code (``exit_codes``). ``session.run`` is the only place that strings them together,
one step per module (``streams``, ``interruption``, ``attempt`` and ``isolation``,
``verdict``, ``reruns``); ``summary`` words what a run says first.
"""
