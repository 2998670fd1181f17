# The repository's top-level folders `shared/`, `workers/` and `services/` are installed as the
# sub-packages of one `graspscape` namespace, so imports read `graspscape.workers.sim...` while
# the tree shows the architecture. Everything else about the package is in pyproject.toml.
from setuptools import find_packages, setup

ROOTS = ("shared", "workers", "services")

packages = [f"graspscape.{root}" for root in ROOTS]
packages += [f"graspscape.{root}.{sub}" for root in ROOTS for sub in find_packages(root)]
# The viewer's page, script and vendored three.js travel with the package (no CDN, no build at
# install); static/built/ holds the atlas's bundle, built from web/bundle/ (build.mjs).
package_data = {"graspscape.services.coordinator.web": ["static/*", "static/vendor/*",
                                                       "static/built/*"]}
setup(packages=packages, package_dir={f"graspscape.{root}": root for root in ROOTS},
      package_data=package_data)
