"""The base of every error that stops a test before it runs, and what the stop means.

Such errors are raised deep (a setting, the coordinator, a share's spec, a refusal) and
answered at the top: the session's result file and exit code, the RUNNER's, the pytest
plugin's exit. Each carries why (:data:`USAGE`: something the user must fix; :data:`BUSY`:
no ID or resources came free, try again) and the outcome its result case records, so
``runner.exit_codes`` turns every one into an exit code in one place.
"""

from __future__ import annotations

#: Something to fix: an argument, a setting, a refusal (a preset ROS_DOMAIN_ID).
USAGE = "usage"
#: The machine was busy: no domain ID, or not the resources asked for, came free.
BUSY = "busy"
#: The result case of a test that could not run.
ERROR = "error"
#: The result case of a test refused on purpose (a preset ID): a failure to fix.
FAILURE = "failure"


class NotRun(Exception):
    """The test was not run; :attr:`reason` and :attr:`outcome` say what that means."""

    reason = USAGE
    outcome = ERROR
