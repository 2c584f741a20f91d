"""The XML schemas of ros-isolated-test's canonical result files.

``junit.xsd`` is a strict subset of the Jenkins xunit-plugin junit-10 schema: a file
valid here is read the same way by colcon test-result, xunit-viewer, Jenkins, GitLab
and the GitHub reporters.
"""

from __future__ import annotations

from functools import cache
from importlib import resources

from lxml import etree

JUNIT_XSD = "junit.xsd"


@cache
def junit_schema() -> etree.XMLSchema:
    """The canonical schema, parsed once per process."""
    data = (resources.files(__name__) / JUNIT_XSD).read_bytes()
    return etree.XMLSchema(etree.fromstring(data))
