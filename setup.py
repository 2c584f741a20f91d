"""The ROS package's build entry: colcon's ament_python build and bloom run this file.

pyproject.toml holds all the metadata (pip reads it alone). Two things are added here for
colcon, whose build runs this file with the environment's own setuptools (68.1 on Ubuntu
24.04, no build isolation) and reads the resulting settings back with ``ast.literal_eval``:

- the ament index marker and ``package.xml`` under ``share/``, beside the CMake package
  that pyproject.toml's data-files install (pyproject.toml's data-files replace any given
  here, so they are added after it is read);
- ``python_requires`` as a plain string: setuptools keeps pyproject.toml's
  ``requires-python`` as a ``SpecifierSet``, whose repr is no literal, and colcon's
  build would stop on it (colcon-core#584).
"""

from setuptools import setup
from setuptools.dist import Distribution

PACKAGE = "ros_isolated_test"
AMENT_FILES = [
    ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
    (f"share/{PACKAGE}", ["package.xml"]),
]


class RosPackage(Distribution):
    """pyproject.toml's settings, plus what a ROS package installs, in literal form."""

    def parse_config_files(self, *args: object, **kwargs: object) -> None:
        super().parse_config_files(*args, **kwargs)
        self.data_files = [*(self.data_files or []), *AMENT_FILES]
        for owner in (self, self.metadata):  # setuptools keeps it in both places
            if getattr(owner, "python_requires", None) is not None:
                owner.python_requires = str(owner.python_requires)


setup(distclass=RosPackage)
