"""Shared test helpers: capability markers, process and scene builders, and helper programs.

Test modules import from here (and from ``conftest``), never from each other. The
``*.py`` programs here are run as processes by the tests (talkers, listeners).
"""
