"""The XML schemas of ros-isolated-test's canonical result files.

``junit.xsd`` is a strict subset of the Jenkins xunit-plugin junit-10 schema: a file
valid here is read the same way by colcon test-result, xunit-viewer, Jenkins, GitLab
and the GitHub reporters.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

from lxml import etree

JUNIT_XSD = "junit.xsd"


@cache
def junit_schema() -> etree.XMLSchema:
    """The canonical schema, parsed once per process."""
    # Beside this module in every install (package data): no importlib.resources needed.
    data = (Path(__file__).parent / JUNIT_XSD).read_bytes()
    return etree.XMLSchema(etree.fromstring(data))
