"""A check of the install: what ``colcon test`` runs for this package in a user's workspace.

Named for what it is: it checks the installed command, RUNNER and pytest plugin, and has
nothing to do with the colcon extension (``ros_isolated_test/colcon/``).

The project's own suite (``tests/``) needs its development venvs; this needs nothing but the
package as colcon installed it, so ``colcon test`` of a workspace that holds this repository
passes quickly, and fails when the install is broken.
"""
