"""Map the repository's top-level folders onto the ``zonecast`` import package.

The repository keeps ``estimator/``, ``service/`` and ``testbed/`` at its top
level (see docs/architecture.md); installed, they are ``zonecast.estimator``,
``zonecast.service`` and ``zonecast.testbed`` so that the project claims one
import name only. Everything else lives in pyproject.toml.
"""

from setuptools import find_packages, setup

TOPS = ("estimator", "service", "testbed")
packages = ["zonecast"] + [f"zonecast.{p}" for p in find_packages(".", include=["zonecast.*"])]
package_dir = {"zonecast": "zonecast"}
for top in TOPS:
    packages.append(f"zonecast.{top}")
    packages += [f"zonecast.{top}.{sub}" for sub in find_packages(top)]
    package_dir[f"zonecast.{top}"] = top

setup(packages=packages, package_dir=package_dir, include_package_data=True)
