"""A tiny action interface package for the tests, built on demand (no action type ships in the
ROS 2 wheels from PyPI, so an rclpy ActionServer needs one of ours).

``build(directory)`` writes ``faultledger_test_actions`` (``action/Count.action``) there and
builds it with CMake into ``directory/install``, the way ``interfaces/build.py`` builds our
interface packages into the venv, but into a prefix of its own: nothing is added to the venv.
A process that imports the package needs ``environment(prefix)`` (its Python package on
``PYTHONPATH``, its libraries on ``LD_LIBRARY_PATH``). A finished build is reused: the
``built`` stamp holds the hash of what was built.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

PACKAGE = "faultledger_test_actions"
ROOT = Path(__file__).resolve().parents[2]
WHEELS_FIX = ROOT / "interfaces" / "pypi_wheels_fix.cmake"

COUNT_ACTION = """\
# Goal: how the server ends it: succeed | abort | cancel (waits for the client's cancel)
string outcome
---
string outcome
---
uint32 step
"""

PACKAGE_XML = f"""\
<?xml version="1.0"?>
<package format="3">
  <name>{PACKAGE}</name>
  <version>0.1.0</version>
  <description>faultledger test actions (built by the tests, never installed)</description>
  <maintainer email="faultledger@example.com">faultledger</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>action_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""

CMAKE_LISTS = f"""\
cmake_minimum_required(VERSION 3.21)
project({PACKAGE})
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
find_package(action_msgs REQUIRED)
rosidl_generate_interfaces(${{PROJECT_NAME}} "action/Count.action" DEPENDENCIES action_msgs)
include("{WHEELS_FIX}")
ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""

FILES = {"package.xml": PACKAGE_XML, "CMakeLists.txt": CMAKE_LISTS,
         "action/Count.action": COUNT_ACTION}


def _hash() -> str:
    digest = hashlib.sha256(sys.prefix.encode())
    for name, text in sorted(FILES.items()):
        digest.update(name.encode() + b"\0" + text.encode() + b"\0")
    digest.update(WHEELS_FIX.read_bytes())
    return digest.hexdigest()


def site_packages(prefix: Path) -> Path:
    return prefix / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"


def build(directory: Path) -> Path:
    """Build (or reuse) the package under ``directory``; returns the install prefix."""
    source, work, prefix = directory / "src", directory / "build", directory / "install"
    stamp = directory / "built"
    wanted = _hash()
    if stamp.is_file() and stamp.read_text().strip() == wanted:
        return prefix
    shutil.rmtree(directory, ignore_errors=True)
    for name, text in FILES.items():
        path = source / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    venv = Path(sys.prefix)
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(
        [str(venv), *filter(None, [env.get("AMENT_PREFIX_PATH")])])
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    steps = [
        ["cmake", "-S", str(source), "-B", str(work), *generator,
         "-DCMAKE_BUILD_TYPE=Release", "-DBUILD_TESTING=OFF",
         f"-DCMAKE_PREFIX_PATH={venv}", f"-DCMAKE_INSTALL_PREFIX={prefix}",
         f"-DPython3_EXECUTABLE={venv / 'bin' / 'python3'}"],
        ["cmake", "--build", str(work), "-j", str(os.cpu_count() or 2)],
        ["cmake", "--install", str(work)],
    ]
    for step in steps:
        result = subprocess.run(step, env=env, capture_output=True, text=True, check=False)
        if result.returncode != 0:
            raise RuntimeError(f"building {PACKAGE}: `{' '.join(step[:3])}` failed:\n"
                               f"{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    stamp.write_text(wanted + "\n")
    return prefix


def environment(prefix: Path) -> dict[str, str]:
    """This process's environment plus what importing the package from ``prefix`` needs."""
    env = dict(os.environ)
    for name, path in (("PYTHONPATH", site_packages(prefix)), ("LD_LIBRARY_PATH", prefix / "lib")):
        env[name] = os.pathsep.join([str(path), *filter(None, [env.get(name)])])
    return env
