"""What ``colcon test`` runs for this package in a user's workspace: a check of the install.

The project's own suite (``tests/``) needs its development venvs; this needs nothing but the
package as colcon installed it, so ``colcon test`` of a workspace that holds this repository
passes quickly, and fails when the install is broken.
"""
