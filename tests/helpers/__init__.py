"""Shared test helpers: one module per job, imported by test modules as ``from helpers...``.

Among them: commands (where the CLI and RUNNER are, running them), results (reading
result files), canonical (what a canonical result file is), domains (picking free IDs),
processes (child processes of a test), workspace (the example colcon package, built once
per session), cmake_package and launch_env (the CMake package's and the launch tier's
builds), peak_rss (a child's memory, never charged with pytest's), distros (the Jazzy and
Kilted venvs, and the environment a sourced setup of each gives), overlap (runners started
at once, proving no two held one ID), readers (how colcon, xunit-viewer, junitparser,
GitLab and Jenkins read a result file), docker_engine (a real Docker engine, the stand-in
base and the project's image, built once), chromium (headless Chromium: a page's DOM, a
screenshot, every request counted), result_tree (a large results tree, made quickly),
imports (the package's import graph from its source: circles, imports against the
layers), capabilities (the only way to skip). Test modules import from here, never from each
other and never from ``conftest``, which holds fixtures only. The other ``*.py`` here are
programs the tests run as processes (talkers, listeners, gate).
"""
