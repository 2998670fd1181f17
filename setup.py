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
# The shipped grippers travel too, as graspscape/configs/grippers/: at the same place relative
# to shared/specs/gripper.py as configs/grippers/ is in the checkout (CONFIG_DIR).
packages.append("graspscape.configs")
package_data["graspscape.configs"] = ["grippers/**/*"]
package_dir = {f"graspscape.{root}": root for root in ROOTS}
package_dir["graspscape.configs"] = "configs"
setup(packages=packages, package_dir=package_dir, package_data=package_data)
