"""The runner: one flow from a parsed request to an exit code.

CLI (``cli``, ``ament_args``) -> environment policy (``environment``) -> domain
coordinator (``ros_isolated_test.domain_coordinator``) -> process supervisor
(``supervisor``, ``capture``) -> result file (``results``) -> exit code
(``exit_codes``). ``session.run`` is the only place that strings them together.
"""
