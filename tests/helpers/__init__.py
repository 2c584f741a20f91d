"""Shared test helpers: one module per job, imported by test modules as ``from helpers...``.

Test modules import from here, never from each other and never from ``conftest``, which
holds fixtures only. Each module's docstring says its job; by kind:

- Running our programs: commands (where the CLI and the RUNNER are, running them),
  cli_runs, partition_runs, reruns, pytest_sessions (real pytest sessions for the
  plugin), launch_runs and launch_files (launch files under pytest, colcon and ctest).
- Reading what a run left: results, canonical, xunit (suites made in code, read back),
  output_capture, report_page and report_text (``report``'s page and lines), consumers
  (how colcon, xunit-viewer, junitparser, GitLab and Jenkins read a result file),
  jenkins_junit10.
- IDs and the machine: domains (picking free IDs), busy_machine (the scene of other ROS
  work for a session), coordinator and holding (holding IDs in other processes),
  hostile_lock_dir, overlap, resource_probe, namespaces, tiny_disk, survivors,
  processes and process_tree (a test's child processes, always ended), peak_rss.
- Builds, made once per session: workspace (the example colcon package), cmake_package,
  ros_package, launch_env, distros (the Jazzy and Kilted venvs), docker_engine,
  result_tree, chromium (headless Chromium: a page's DOM, a screenshot, every request).
- The repository itself: docs, imports (the import graph: circles, imports against the
  layers), layout (where each test lives).
- capabilities: the only way to skip.

The other modules here are programs the tests run as processes (crowd_probe,
daemon_talker, gate, gz_probe, host_talker, listener, token_exchange, token_listener).
"""
